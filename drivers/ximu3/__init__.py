"""x-IMU3 (x-io Technologies): the data logs its GUI writes (``log``)."""

from .log import DeviceLog, LogError, read_device_log, read_log

__all__ = ["DeviceLog", "LogError", "read_device_log", "read_log"]
