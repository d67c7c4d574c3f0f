"""The wire formats ``softtip live --port PORT --driver NAME`` reads, each a registered :class:`Driver`.

softtip's own are its firmware's frames (``softtip``, :class:`FirmwareStream`) and the binary records of
a ReSkin / AnySkin board (``reskin`` and ``anyskin``: the boards send the same records). A system
registers another (``System.drivers``: name -> ``"module:attribute"`` of a :class:`Driver`, imported
when a port is opened with it); a name of softtip's own stays softtip's.

A driver turns a :class:`PortRequest` into a :class:`~softtip.hardware.ThreadedSource`: the live
session opens it, builds its pipeline for the chips, reading and settings the source states, and
starts it.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Self

from softtip._core.channels import MAGNETIC
from softtip._core.systems import own_or_declared
from softtip.hardware.driver import FingertipDriver, Sample
from softtip.hardware.paced import ThreadedSource
from softtip.hardware.reskin import RESKIN_CHIPS, ReSkinStream
from softtip.sensors.mlx90393 import SENSOR as MLX90393_SENSOR
from softtip.sensors.registry import ChipSettings

DEFAULT_RATE_HZ = 50


@dataclass(frozen=True)
class PortRequest:
    """What a command asks of the board on ``port``: ``chips`` (None: as it reports, or the driver's
    default), ``rate_hz`` (None: the driver's default) and ``settings`` (its chips' registered sensor at
    the settings to write; None: the driver's default)."""

    port: str
    chips: int | None = None
    rate_hz: int | None = None
    settings: ChipSettings | None = None


@dataclass(frozen=True)
class Driver:
    """A wire format: ``source(request)`` returns the board on ``request.port`` as a live source, not yet
    opened; ``own_rate``: the board streams at a rate of its own, so a requested rate is refused."""

    name: str
    title: str
    source: Callable[[PortRequest], ThreadedSource]
    own_rate: bool = False


def firmware_settings(settings: ChipSettings | None) -> ChipSettings:
    """The settings softtip's firmware writes to its chips: ``settings`` (None: the chip's power-on
    defaults); another sensor's are refused in one line."""
    if settings is None:
        return MLX90393_SENSOR.at(MLX90393_SENSOR.settings())
    if settings.kind != MLX90393_SENSOR:
        raise ValueError(f"settings: softtip's firmware reads {MLX90393_SENSOR.title} chips, not sensor "
                         f"{settings.kind.name!r}")
    return settings


class FirmwareStream:
    """softtip's fingertip firmware on a serial port as a live source: ``open()`` waits for the board,
    checks the chips it reports against those asked for and writes the settings and rate; ``start``
    starts the stream. Its chips are MLX90393s (the firmware configures their registers)."""

    reading = MAGNETIC
    finished = False  # a board streams until it is closed

    def __init__(self, request: PortRequest) -> None:
        self.settings = settings = firmware_settings(request.settings)
        self.rate_hz = DEFAULT_RATE_HZ if request.rate_hz is None else request.rate_hz
        self._chips = request.chips
        self._port = request.port
        self._deliver: Callable[[Sample], None] | None = None
        self.driver = FingertipDriver(request.port, settings=settings.values, rate_hz=self.rate_hz,
                                      callback=self._forward, queue_size=0)

    @property
    def name(self) -> str:
        """The device's name once it has answered, else its port."""
        return self._port if self.driver.identity is None else self.driver.identity.name

    @property
    def chips(self) -> int | None:
        return self._chips if self.driver.identity is None else self.driver.identity.chips

    def open(self) -> Self:
        self.driver.open()
        reported = self.driver.identity.chips
        if self._chips not in (None, reported):
            self.driver.close()
            raise ValueError(f"chips = {self._chips}: the device at {self._port!r} reports {reported}")
        return self

    def start(self, deliver: Callable[[Sample], None]) -> Self:
        self._deliver = deliver
        self.driver.start()
        return self

    def _forward(self, sample: Sample) -> None:
        self._deliver(sample)  # the driver streams only after start() has set it

    def counters(self) -> dict:
        stats = self.driver.stats
        return {"delivered": stats.frames, "lost_in_transit": stats.dropped, "crc_errors": stats.crc_errors,
                "malformed": stats.malformed, "bytes_discarded": stats.bytes_discarded,
                "reconnects": stats.reconnects}

    def close(self) -> None:
        self.driver.close()


def _board_records(name: str) -> Callable[[PortRequest], ThreadedSource]:
    def source(request: PortRequest) -> ThreadedSource:
        if request.settings is not None:
            raise ValueError(f"settings: a {name} board's firmware sets its own chips; give none")
        return ReSkinStream(request.port, request.chips or RESKIN_CHIPS, name=name)
    return source


OWN = {driver.name: driver for driver in (
    Driver("softtip", "softtip's fingertip firmware", FirmwareStream),
    Driver("reskin", f"a ReSkin board's binary records ({RESKIN_CHIPS} chips unless told)", _board_records("reskin"),
           own_rate=True),
    Driver("anyskin", f"an AnySkin board's binary records ({RESKIN_CHIPS} chips unless told)",
           _board_records("anyskin"), own_rate=True))}


def driver(name: str) -> Driver:
    """The driver ``name``: softtip's own, or a registered system's (imported now); another name is
    refused in one line with the known ones."""
    return own_or_declared("driver", name, OWN, Driver, "driver")
