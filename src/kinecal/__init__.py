"""kinecal: kinematic and joint-compliance calibration of robots and robotic vision systems.

The method follows Ye et al., "Kinematic and Joint Compliance Modeling Method to Improve
Position Accuracy of a Robotic Vision System", Sensors 24(8), 2559 (2024).
Subpackages are imported on demand so ``kinecal --help`` starts fast; so are
:func:`keep_freed_memory` (ctypes) and :class:`one_blas_thread` (the BLAS thread limit the
library's entry points run under, restoring the caller's setting; usable around any code).
"""

from typing import TYPE_CHECKING

from kinecal import _lazy
from kinecal._version import __version__

if TYPE_CHECKING:
    from kinecal._blas import one_blas_thread
    from kinecal._memory import keep_freed_memory

__all__ = ["__version__", "keep_freed_memory", "one_blas_thread"]

__getattr__, __dir__ = _lazy.exports(
    __name__,
    {
        "_version": ("__version__",),
        "_memory": ("keep_freed_memory",),
        "_blas": ("one_blas_thread",),
    },
)
