"""The OpenCL runtime and kernel sources shared by every device program (pyopencl imported
lazily: importing this package needs no OpenCL).

- `runtime`: device choice (`select_device`, EEGT_OPENCL_DEVICE), one context, queue and
  program cache per device (`runtime()`, `Runtime.build`), the process-wide `LOCK`.
- `build`: program sources (`common.cl` in front of each file, `program_source`) and build
  options: host constants as `-D` defines (`cl_defines`), core.fpmath's (`fpmath_options`),
  the EEGT kernels' size class (`program_size`, `eegt_options`).
- kernels: `common.cl` (NumPy's pairwise sums, fpmath's log / exp / power, math macros),
  `eegt_kernels.cl` (the EEGT iteration: `core.eegt.engine_opencl`), `lbfgs_parallel.cl` (the
  global stage's many-work-item L-BFGS: `core.optimize.solver_parallel`), `lbfgs_single.cl`
  (its single-work-item kernel: `core.optimize.solver_opencl`).
"""
