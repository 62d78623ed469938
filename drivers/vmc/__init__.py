"""VR headset, controllers and trackers as VMC protocol device messages (OSC over UDP):
``protocol`` (pure encode/decode and Unity's frame -> ours), ``device`` (``vmc-in://``)."""
