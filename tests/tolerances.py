"""Tolerances used across the tests, in one table (SI unless the name says otherwise)."""

# Round trips of exact maps (exp/log, Euler, quaternions, packing).
ROUND_TRIP = 1e-12
# Central finite differences with h ~ 1e-6 on O(1) functions: truncation ~h^2, rounding ~eps/h.
FD_REL = 1e-6
FD_STEP = 1e-6
# Test vectors are printed with 4 decimals in mm: half a unit of the last digit.
VECTOR_ROUNDING_MM = 5e-5
# Agreement with an independent implementation of the same URDF (double precision).
INDEPENDENT_MM = 1e-6
