"""Hardware layer: the fingertip serial protocol, the host driver, a ReSkin reader, a pty emulator
(in this process or a child process) and a paced source (readings played at their rate, for a
sensor with no softtip firmware)."""

from softtip.hardware.driver import (DeviceDisconnected, DeviceError, DeviceTimeout, DriverStats, FingertipDriver,
                                     PortError, Sample, StreamTracker, open_serial, temperature_C, temperature_to_raw)
from softtip.hardware.emulator import Emulator, FaultPlan, FrameFate, LoggedFrame
from softtip.hardware.emulator_process import EmulatorLog, EmulatorProcess, PressCycle
from softtip.hardware.paced import PacedSource
from softtip.hardware.protocol import (Ack, ChipStatus, Command, CommandError, DataFlag, ErrorCode, ErrorReply, Frame,
                                       FrameDecoder, FrameType, Identity, crc16_ccitt_false, encode_frame)
from softtip.hardware.reskin import ReSkinDecoder, ReSkinReader

__all__ = [
    "Ack",
    "ChipStatus",
    "Command",
    "CommandError",
    "DataFlag",
    "DeviceDisconnected",
    "DeviceError",
    "DeviceTimeout",
    "DriverStats",
    "Emulator",
    "EmulatorLog",
    "EmulatorProcess",
    "ErrorCode",
    "ErrorReply",
    "FaultPlan",
    "FingertipDriver",
    "Frame",
    "FrameDecoder",
    "FrameFate",
    "FrameType",
    "Identity",
    "LoggedFrame",
    "PacedSource",
    "PortError",
    "PressCycle",
    "ReSkinDecoder",
    "ReSkinReader",
    "Sample",
    "StreamTracker",
    "crc16_ccitt_false",
    "encode_frame",
    "open_serial",
    "temperature_C",
    "temperature_to_raw",
]
