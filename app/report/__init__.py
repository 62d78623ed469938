"""The gait report (``imucap report``): a recorded walk's strides, joint ranges and angles over the gait
cycle, how sure each figure is, and a comparison with an earlier session, as HTML and PDF.

Parts, bottom to top: ``events`` (foot strike and foot off from contact signals, debounced), ``strides``
(each stride's parameters, which strides count), ``angles`` (which joint angles, from
``inference.metrics.joint_angles``), ``analysis`` (one walk analysed, its JSON figures), ``normal`` (the
comparison band from motion capture walks), ``confidence`` (measured / inferred, spread, expected error),
``compare`` (two sessions), ``session`` (the first page's facts), ``plots``, ``html``, ``browser``
(headless Chromium for the PDF), ``build`` (``make_report``). docs/report.md.
"""

from app.report.build import Report, make_report

__all__ = ["Report", "make_report"]
