"""How a run uses the process it runs in: NumPy's page advice, the allocator's freed memory
and a second thread for set-up. Each setting is made when a run starts and put back when the
last run ends; none is made at import, and none changes a result's bits.

- page advice (`page_advice.pages_for_run`; ordinary pages from the first run on unless
  EEGT_HUGE_PAGES=1): docs/scale.md.
- freed memory kept while a large run works: `heap.keep_freed_memory`.
- the shared counter behind both: `run_scoped.RunScoped`; two pieces of set-up at once:
  `side_by_side.side_by_side` (the module keeps the name; the face does not export the
  function, so `core.host.side_by_side` stays the module).
"""

from .heap import keep_freed_memory
from .page_advice import pages_for_run, prefer_ordinary_pages
from .run_scoped import RunScoped

__all__ = ["RunScoped", "keep_freed_memory", "pages_for_run", "prefer_ordinary_pages"]
