"""kinecal: kinematic and joint-compliance calibration of robots and robotic vision systems.

The method follows Ye et al., "Kinematic and Joint Compliance Modeling Method to Improve
Position Accuracy of a Robotic Vision System", Sensors 24(8), 2559 (2024).
Subpackages are imported on demand so ``kinecal --help`` starts fast.
"""

from kinecal._memory import keep_freed_memory
from kinecal._version import __version__

__all__ = ["__version__", "keep_freed_memory"]
