"""movella-dot:// takes a MAC address (BlueZ, Windows) or a CoreBluetooth UUID (macOS), and
nothing else, in one line."""

from __future__ import annotations

import pytest

import drivers
from drivers.movella_dot.driver import is_ble_address


def test_mac_and_corebluetooth_uuid_addresses(tmp_path):
    assert is_ble_address("D4:22:CD:00:01:27") and is_ble_address("6E400001-B5A3-F393-E0A9-E50E24DCCA9E")
    assert not is_ble_address("D4:22:CD:00:01") and not is_ble_address("6E400001-B5A3-F393-E0A9")
    uuid = "6e400001-b5a3-f393-e0a9-e50e24dcca9e"
    dev = drivers.make_device(f"movella-dot://{uuid}?ble={tmp_path}")
    assert dev.address == uuid.upper() and dev.describe() == f"movella-dot://{uuid.upper()}?ble={tmp_path}"
    with pytest.raises(ValueError, match="CoreBluetooth UUID"):
        drivers.make_device("movella-dot://my-dot")
