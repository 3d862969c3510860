"""numba options shared by every compiled kernel (blob detection, tracking).

- ``cache=True``: the machine code is kept on disk beside the kernel's module, so
  a new process (or a worker) loads it instead of compiling;
- ``nogil=True``: a thread running a kernel lets the others run;
- ``JIT`` adds ``fastmath={"reassoc"}``: sums may be reordered so that they are
  vectorised; nothing else of IEEE arithmetic is relaxed.  ``JIT_EXACT`` is for
  kernels that must do numpy's arithmetic operation for operation (their results
  are compared with numpy's to the bit).

Cached kernels must not contain numpy array expressions (docs/blobs.md, "Cached
kernels and array expressions"): write explicit loops.
"""
#: Options of the kernels that may reorder sums.
JIT = dict(cache=True, nogil=True, fastmath={"reassoc"})
#: Options of the kernels that must do numpy's arithmetic operation for operation (no ``fastmath``).
JIT_EXACT = dict(cache=True, nogil=True)
