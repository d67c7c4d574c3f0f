"""Hardware layer: the fingertip serial protocol, the host driver, a pty emulator (in this process or
a child process), a ReSkin / AnySkin reader, live source and board emulator, and a paced source
(readings played at their rate, for a sensor with no softtip firmware)."""

from softtip.hardware.driver import (DeviceDisconnected, DeviceError, DeviceTimeout, DriverStats, FingertipDriver,
                                     PortError, Sample, StreamTracker, open_serial, temperature_C, temperature_to_raw)
from softtip.hardware.emulator import Emulator, FaultPlan, FrameFate, LoggedFrame
from softtip.hardware.emulator_process import EmulatorLog, EmulatorProcess, PressCycle
from softtip.hardware.paced import PacedSource, ThreadedSource
from softtip.hardware.protocol import (Ack, ChipStatus, Command, CommandError, DataFlag, ErrorCode, ErrorReply, Frame,
                                       FrameDecoder, FrameType, Identity, crc16_ccitt_false, encode_frame)
from softtip.hardware.reskin import ReSkinBoard, ReSkinDecoder, ReSkinReader, ReSkinStream

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
    "ReSkinBoard",
    "ReSkinDecoder",
    "ReSkinReader",
    "ReSkinStream",
    "Sample",
    "StreamTracker",
    "ThreadedSource",
    "crc16_ccitt_false",
    "encode_frame",
    "open_serial",
    "temperature_C",
    "temperature_to_raw",
]
