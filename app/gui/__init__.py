"""The Qt user interface (PySide6 + pyqtgraph). Imported only when a window is wanted, so
headless use never loads Qt."""
