"""numba options shared by every compiled kernel (blob detection, tracking).

- ``cache=True``: the machine code is kept on disk beside the kernel's module, so
  a new process (or a worker) loads it instead of compiling;
- ``nogil=True``: a thread running a kernel lets the others run;
- ``JIT`` adds ``fastmath={"reassoc", "contract"}``: sums may be reordered so
  that they are vectorised, and a product added to a sum may be one fused
  multiply-add (rounded once, not twice); nothing else of IEEE arithmetic is
  relaxed.  Only the blob kernels use it: their answers are stored as float32
  centres and float16 axes, and on 144 sample frames of both colours the
  detections came out identical to the byte with and without ``contract``
  (docs/blobs.md, "Speed"), 4-8 % less CPU an image.  ``JIT_EXACT`` is for
  kernels that must do numpy's arithmetic operation for operation (their results
  are compared with numpy's to the bit; the tracker uses only these).

numba's disk cache is keyed by each kernel's source file (its modification time and
size) and signature, not by these options: after changing them, change the kernels'
modules too (or delete their ``__pycache__``), or processes keep loading the code
compiled with the old options.

Cached kernels must not contain numpy array expressions (docs/blobs.md, "Cached
kernels and array expressions"): write explicit loops.
"""
#: Options of the kernels that may reorder sums.
JIT = dict(cache=True, nogil=True, fastmath={"reassoc", "contract"})
#: Options of the kernels that must do numpy's arithmetic operation for operation (no ``fastmath``).
JIT_EXACT = dict(cache=True, nogil=True)
