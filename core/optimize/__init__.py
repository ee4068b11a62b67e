"""The global stage: optimisation-based untangling and quality polishing (beyond the paper).

Where things live (NumPy and OpenCL twins side by side; the kernels are in `core/opencl/`):

- mesh tables, corner triangles, reference sizes: `mesh_tables.py` (uploaded by the solvers).
- foldover-free energy f, g, chi (Garanzha et al.): `energy.FoldoverEnergy`;
  OpenCL: `lbfgs_parallel.cl` (`fold_*` kernels), `lbfgs_single.cl` `fold_value_grad`.
- lift energy (mean ratio + floor + barrier): `energy.LiftEnergy`;
  OpenCL: `lbfgs_parallel.cl` (`lift_*` kernels), `lbfgs_single.cl` `lift_value`, `lift_grad`.
- L-BFGS (two-loop, Armijo backtracking, validity guard), three implementations of one
  `dispatch.Solver` protocol with the same bits: `solver.lbfgs` (NumPy);
  `solver_parallel.ParallelLbfgs` (many work-items: per-corner energy kernels, per-node
  gathers, NumPy's pairwise sums as fixed-order block reductions; `lbfgs_parallel.cl`);
  `solver_opencl.OpenCLLbfgs` (one work-item runs the whole solve; `lbfgs_single.cl`, whose
  `fold_value_grad` / `lift_value` / `lift_grad` are the energies written out).
- which solver runs (the whole rule): `dispatch` (`uses_device`, `on_host`, `route`,
  `SMALL_CORNERS`); the device solver of a run: `device.solver_for`.
- step limit (the first det root along a search direction: guarded line searches skip the
  trial steps past it, same iterates): `energy.FoldoverEnergy.step_limit`,
  `state.skipped_trials`, computed after an iteration with a `state.folded_trial`; OpenCL:
  `lbfgs_parallel.cl` `limit_corner`, `finish_limit`.
- active sub-mesh (rings around seed elements): `submesh.Neighbourhood` (node -> element
  incidence built once, each sub-mesh costs its own size), `submesh.active_submesh`.
- stage drivers (eps continuation and polish, the lift; giving up on a fold that makes no
  progress, `stages.STALL_ROUNDS`): `stages.untangle_global`,
  `stages.lift_min_quality`; what they are handed: `options.GlobalOptions`.
- boundary sliding (a sliding node's parameter on its curve as its variable, order kept in
  the line search): `slide.SlideState`, `slide.SlideProblem` (host solver only).

- the kernels' constants (energy.THETA, LIFT_PENALTY, LIFT_BARRIER; state.TRIALS, ARMIJO,
  CURVATURE, LIMIT_MARGIN; the state buffers' layouts, NumPy's summation cut points) are
  defined in Python only and reach the .cl sources as `-D` build defines:
  `solver_opencl.build_options`, `solver_parallel.build_options`.

The EEGT iteration itself (stretch, stitching with the weights f(d) g(q) of eq. 20-21) and
the rest of the core are mapped in `core/__init__.py`.
"""

from .options import GlobalOptions
from .stages import STALL_ROUNDS, Resume, lift_min_quality, untangle_budget, untangle_global
from .state import stops
from .submesh import active_submesh

__all__ = ["STALL_ROUNDS", "GlobalOptions", "Resume", "active_submesh", "lift_min_quality",
           "stops", "untangle_budget", "untangle_global"]
