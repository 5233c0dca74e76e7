"""The ADIS16364 itself, shared by the recording and the analysis side: register map, burst
layout, scale factors and configuration (:mod:`.adis16364`), and the MCAP frame schema
(:mod:`.frame_schema`)."""

from imupipe.device.adis16364 import DeviceConfig, FrameBlock, config_for_rate
from imupipe.device.frame_schema import METADATA_NAME, SCHEMA_NAME

__all__ = ["METADATA_NAME", "SCHEMA_NAME", "DeviceConfig", "FrameBlock", "config_for_rate"]
