"""Movella (Xsens) DOT over Bluetooth LE: measurement payloads (``protocol``), the BLE
seam (``ble_seam``: bleak, or sockets for the twin) and the driver."""
