"""What is plugged in or in range that imucap can open: serial ports, HID and USB devices,
CAN interfaces, Movella DOTs over Bluetooth LE (and simulated ones in the seam's socket
folders), each with the URL that would open it.

Why below both the CLI and the window: `imucap devices list` prints it and the window's
devices panel lists it, and the window must not import the CLI.
"""

from __future__ import annotations

import os
from typing import Any

SIM_BLE_FOLDER = "/tmp/imucap-sim/ble"  # where `imucap devices simulate --protocol movella-dot` puts its DOT
BLE_SCAN_S = 3.0

# USB ids we recognise -> (what it is, backend scheme)
KNOWN_USB: dict[tuple[int, int | None], tuple[str, str]] = {
    (0x2639, None): ("Xsens MTi (USB)", "xbus"),
    (0x0403, 0xD38B): ("Xsens USB-serial converter", "xbus"),
    (0x054C, 0x0CE6): ("Sony DualSense", "dualsense"),
    (0x054C, 0x0DF2): ("Sony DualSense Edge", "dualsense"),
    (0x10C4, 0xEA60): ("CP210x USB-UART (BNO08x RVC boards)", "bno08x-rvc"),
    (0x1A86, 0x7523): ("CH340 USB-UART (BNO08x RVC boards)", "bno08x-rvc"),
}


def _known(vid: int | None, pid: int | None) -> tuple[str, str] | None:
    if vid is None:
        return None
    return KNOWN_USB.get((vid, pid)) or KNOWN_USB.get((vid, None))


def discover() -> list[dict[str, Any]]:
    """Everything we can see, each with the URL that would open it (if any)."""
    found: list[dict[str, Any]] = []
    try:
        from serial.tools import list_ports

        for p in list_ports.comports():
            k = _known(p.vid, p.pid)
            url = f"{k[1]}://{p.device}" if k and k[1] != "dualsense" else None
            found.append(
                {
                    "kind": "serial",
                    "path": p.device,
                    "usb": _usb(p.vid, p.pid),
                    "what": k[0] if k else p.description,
                    "url": url,
                }
            )
    except Exception as exc:  # discovery must never take the command down
        found.append({"kind": "serial", "error": str(exc)})
    try:
        import hid

        for d in hid.enumerate():
            k = _known(d.get("vendor_id"), d.get("product_id"))
            if k is None:
                continue
            serial = d.get("serial_number") or ""
            found.append(
                {
                    "kind": "hid",
                    "path": d.get("path", b"").decode(errors="replace"),
                    "usb": _usb(d.get("vendor_id"), d.get("product_id")),
                    "what": k[0],
                    "url": "dualsense://" + (f"?serial={serial}" if serial else ""),
                }
            )
    except Exception as exc:
        found.append({"kind": "hid", "error": str(exc)})
    try:
        import usb.core

        for d in usb.core.find(find_all=True) or []:
            k = _known(d.idVendor, d.idProduct)
            if k is not None:
                found.append(
                    {
                        "kind": "usb",
                        "path": f"bus {d.bus} address {d.address}",
                        "usb": _usb(d.idVendor, d.idProduct),
                        "what": k[0],
                        "url": None,
                        "note": f"opened through its {k[1]} interface (serial port or HID)",
                    }
                )
    except Exception as exc:  # no libusb backend, no permission: say so, go on
        found.append({"kind": "usb", "error": str(exc)})
    try:
        import can

        for cfg in can.detect_available_configs(interfaces=["socketcan"]):
            found.append(
                {
                    "kind": "can",
                    "path": f"{cfg['interface']}/{cfg['channel']}",
                    "what": "CAN interface",
                    "url": f"xsens-can://{cfg['interface']}/{cfg['channel']}",
                }
            )
    except Exception as exc:
        found.append({"kind": "can", "error": str(exc)})
    found += discover_dots()
    return found


def discover_dots(scan_s: float = BLE_SCAN_S) -> list[dict[str, Any]]:
    """DOTs in range (bleak), then simulated ones in the seam folders of ``IMUCAP_BLE_SOCKETS``
    (os.pathsep separated) and ``SIM_BLE_FOLDER``: name, address, battery, URL."""
    from drivers.movella_dot.ble_seam import SocketSeam
    from drivers.movella_dot.driver import list_dots

    found: list[dict[str, Any]] = []
    try:
        found += list_dots(None, scan_s)
    except Exception as exc:  # no adapter, no BlueZ/D-Bus, no permission
        why = f"{type(exc).__name__}: {exc}"
        found.append({"kind": "ble", "error": f"no Bluetooth LE scan (no adapter or BlueZ reachable: {why})"})
    folders = [f for f in os.environ.get("IMUCAP_BLE_SOCKETS", "").split(os.pathsep) if f] + [SIM_BLE_FOLDER]
    for folder in dict.fromkeys(folders):
        if os.path.isdir(folder):
            try:
                found += [dict(d, what=f"{d['what']} (simulated)") for d in list_dots(SocketSeam(folder), 1.0)]
            except Exception as exc:
                found.append({"kind": "ble", "error": f"{folder}: {exc}"})
    return found


def _usb(vid: int | None, pid: int | None) -> str | None:
    return None if vid is None else f"{vid:04x}:{(pid or 0):04x}"
