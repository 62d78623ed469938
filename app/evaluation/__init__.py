"""Evaluation helpers of the application: what ``imucap evaluate`` needs from the layers that
inference's evaluation harness may not import (``tracked_points``: a VR rig's tracked points
read through the drivers' own code)."""
