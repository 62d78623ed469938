"""Many devices at once, merged on one session clock and put on the 60 Hz grid.

Why each piece exists:

- Readers: one selector thread serves every device with a socket (UDP): it
  wakes once per ``read_interval``, not once per packet, and drains each ready
  device with ``read_many``, so 13 sensors at 100 Hz cost ~100 wake-ups a second
  instead of 1300. Queue-backed transports (python-can's virtual bus, the HID
  seam) and serial ports keep a thread of their own (a terminal's ``select`` can
  wait in the kernel for seconds: ``readers``), and a socket device gets one
  while it reconnects, so a slow handshake never delays the others.
- Bounded queues between readers and the consumer: if the consumer (inference,
  GUI) falls behind, the oldest samples are dropped and counted, and grid frames
  older than ``max_backlog`` are skipped and counted, so the output always
  describes *now* instead of lagging further and further.
- A clock model per device (``ClockModel``): arrival times are jittered by the
  OS and the transport, device clocks are smooth but offset and drifting. A
  running linear fit of arrival time against device time, taken through the
  lower envelope of the arrivals (transport delay is never negative), gives
  jitter-free session times.
- Counter gaps become per-sensor gaps: grid points that fall between two
  samples with lost packets between them are marked missing, not held over;
  when interpolating, a gap no longer than ``fill_gap`` is interpolated across
  instead (below).
- The grid: frames at k / rate on the session clock. The default is the latest
  sample held, missing when older than ``staleness``. To interpolate instead the
  caller passes an ``Interpolation`` (``grid.py``): the slerp to blend two
  orientations with, which the app takes from inference; drivers import nothing
  of ours (layering), hence the callable.
- ``latency``: how far behind now the grid runs. Interpolating needs the sample
  *after* a grid time, so it waits for the next sample of every site; holding
  only needs the sample at or before it to have been read, a few milliseconds
  (the low-latency mode, docs/latency.md).
- A device of kind ``tracked`` (a VR rig, ``drivers/vmc``) is one device and several
  sites: read once, on one clock model (its sites share the sender's clock), its samples
  routed by ``extra["site"]`` into a ring per site (``Track.site_rings``), each a site of
  the frame like an IMU's. Its positions (``extra["position"]``) go into the same rings and
  onto the grid as the free acceleration does (held, or blended between the same two
  samples): ``HubFrame.position``, NaN at IMU sites, None from a hub with no tracked device.
- Each frame says which sample of each site went into it last (``sample_t``,
  ``sample_counter``), so a latency measurement starts at a real sample.
- ``latency`` (how far behind now the grid runs) and ``max_latency`` (how far it
  may fall further behind for samples that reach it late): ``hub.py``.

Where each piece lives: ``readers`` (the threads, each device's ``Track``), ``clock``
(``ClockModel``), ``grid`` (the sample rings, hold and interpolation), ``hub`` (``Hub``: the
queues drained onto the session clock, the wait for late samples, the frames).
"""

from drivers.hub.clock import ClockModel
from drivers.hub.grid import Interpolation, Slerp, StreamResampler
from drivers.hub.hub import LATE_PERSIST_S, LATE_QUIET_S, Hub, HubFrame, HubStats

__all__ = ["ClockModel", "Hub", "HubFrame", "HubStats", "Interpolation", "LATE_PERSIST_S", "LATE_QUIET_S", "Slerp",
           "StreamResampler"]
