"""Evaluation helpers of the application: what ``imucap evaluate`` needs from the layers that
inference's evaluation harness may not import (``tracked_points``: a VR rig's tracked points
read through the drivers' own code), and the real-data yardstick of ``--data @real``
(``real``: the real logs replayed with fewer sensors, scored against the left-out ones;
``phases``: walking, turning, standing from the sensors; ``offset``: the constant and the
dynamic part of an error)."""
