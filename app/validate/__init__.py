"""Validation against a lab's reference system (``imucap validate``): read another system's
answer for the same trial (BVH, MVNX, C3D, TRC, OpenSim .mot/.sto, imucap's truth .npz),
find the time offset and the heading between the two, and report what a validation paper
reports (per-segment orientation error, per-joint flexion RMS and range, Bland-Altman of
the ranges, a standing-pose baseline). docs/validation.md has the definitions."""
