"""Run inside Blender (background): the UV map of object "Tangled" in two .blend files,
checked by meshcheck.uv_check (not the extension's code). Args after --: IN.blend OUT.blend
RESULT.json; writes {"in": ..., "out": ..., "border_kept": bool, "pins_kept": bool,
"positions_kept": bool, "moved": loops moved}."""
import json
import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import meshcheck
from bl_uv_read import read

inp, out, result = sys.argv[sys.argv.index("--") + 1:][:3]
uv0, pins0, co0, cv, faces = read(inp, "Tangled")
uv1, pins1, co1, _, _ = read(out, "Tangled")
c0, c1 = meshcheck.uv_check(uv0, faces, cv), meshcheck.uv_check(uv1, faces, cv)
border = c0.pop("border_loops")
c1.pop("border_loops")
with open(result, "w") as fh:
    json.dump({"in": c0, "out": c1,
               "border_kept": bool(np.array_equal(uv0[border], uv1[border])),
               "pins_kept": bool(pins0.any() and np.array_equal(uv0[pins0], uv1[pins0])),
               "positions_kept": bool(np.array_equal(co0, co1)),
               "moved": int(np.any(uv0 != uv1, axis=1).sum())}, fh)
print("E2E-UV-CHECK written", result)
