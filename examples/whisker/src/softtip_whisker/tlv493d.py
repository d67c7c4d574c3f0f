"""The Infineon TLV493D-A1B6 3-D Hall sensor as the host reads it: 12-bit two's-complement words per axis
(or their 8 most significant bits in the fast readout), 98 µT per word step, clipped at the words' ends.

Figures from the TLV493D-A1B6 data sheet (Rev. 1.1, 2019-04-09) and its user manual (V1.03, 2018-02-20):
linear range ±130 mT per axis, 12-bit data per axis, 98 µT per LSB (the 8-bit readout drops the 4 least
significant bits: 16 LSB, 1.568 mT), update rates of 3.3 kHz (fast mode), 100 Hz (low-power mode) and
10 Hz (ultra-low-power mode), and a typical magnetic noise of 0.1 mT rms per axis. Infineon's Arduino
library for the chip (TLV493D-A1B6-3DMagnetic-Sensor) decodes with the same 0.098 mT per word, reads the
8-bit values from the high bytes alone and waits 10 ms and 100 ms per measurement in the two low-power
modes.

Where these two figures are checked outside the data sheet: the fast mode's 3.3 kHz is the Linux kernel's
driver's (drivers/iio/magnetometer/tlv493d.c, after the user manual: 305 µs per measurement in fast and
master-controlled modes, 10 ms in low-power, 100 ms in ultra-low-power); the 0.1 mT is how Infineon's
maintainer of that library quotes the data sheet's typical error per axis (its issue 11, 2019), and a
board at rest posted in its issue 13 reads words spread by 1.35, 0.86 and 0.55 steps (132, 84 and 54 µT
rms over 22 readings, x, y, z): the figure is the chip's order of noise, a board's own may differ.
"""

from __future__ import annotations

import numpy as np

from softtip.plugin import MAGNETIC, Acquisition, SensorKind, choice, schema

STEP_12_BIT_UT = 98.0  # data sheet: "resolution 98 µT/LSB"
LINEAR_RANGE_UT = 130_000.0  # data sheet: linear field measurement up to ±130 mT
UPDATE_RATE_HZ = {"fast": 3300.0, "low-power": 100.0, "ultra-low-power": 10.0}
NOISE_UT = 100.0  # data sheet: magnetic noise 0.1 mT rms, typical


@schema(section="sensor")
class TLV493DSettings:
    """What a host sets: the power mode (its update rate) and the readout's bits per axis."""

    mode: choice("fast", "low-power", "ultra-low-power") = "low-power"
    bits: choice(12, 8) = 12

    @classmethod
    def from_dict(cls, table: dict) -> TLV493DSettings:
        return cls(**table)

    def to_dict(self) -> dict:
        return {"mode": self.mode, "bits": self.bits}

    @property
    def rate_hz(self) -> float:
        return UPDATE_RATE_HZ[self.mode]


def _word_limits(settings: TLV493DSettings) -> tuple[int, int]:
    half = 1 << (settings.bits - 1)
    return -half, half - 1


def step_uT(settings: TLV493DSettings) -> np.ndarray:
    """The output step per axis (µT): 98 µT at 12 bits, 16 times that at 8."""
    return np.full(3, STEP_12_BIT_UT * (1 << (12 - settings.bits)))


def full_scale_uT(settings: TLV493DSettings) -> np.ndarray:
    """The largest magnitude per axis the words hold unclipped (µT): the top word's field."""
    return step_uT(settings) * _word_limits(settings)[1]


def noise_uT(settings: TLV493DSettings) -> np.ndarray:
    """Its rms noise per axis (µT): the data sheet's typical figure, in every mode."""
    return np.full(3, NOISE_UT)


def update_time_s(settings: TLV493DSettings) -> float:
    """The seconds between two readings in its power mode."""
    return 1.0 / settings.rate_hz


def signed_words(field_T: np.ndarray, settings: TLV493DSettings, rng: np.random.Generator | None,
                 noise_uT: float) -> np.ndarray:
    """The signed words (..., 3) the chip outputs for fields ``field_T`` (..., 3, tesla): the field plus white
    noise of ``noise_uT`` rms (none without ``rng``), rounded to the output step and clipped at the words' ends."""
    field_uT = np.asarray(field_T, dtype=np.float64) * 1e6
    noisy = field_uT if rng is None else field_uT + rng.normal(0.0, noise_uT, field_uT.shape)
    return np.clip(np.rint(noisy / step_uT(settings)), *_word_limits(settings)).astype(np.int64)


def read_uT(field_T: np.ndarray, settings: TLV493DSettings, rng: np.random.Generator,
            noise_uT: float) -> tuple[np.ndarray, np.ndarray]:
    """What the host reads of fields ``field_T`` (..., 3, tesla): (values in µT, saturated), with white noise
    of ``noise_uT`` rms."""
    words = signed_words(field_T, settings, rng, noise_uT)
    lowest, highest = _word_limits(settings)
    return words * step_uT(settings), (words <= lowest) | (words >= highest)


def decode(settings: TLV493DSettings, words: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Raw words (..., 3) as the registers assemble them (0 .. 2^bits - 1, two's complement) into
    (values in µT, saturated)."""
    words = np.asarray(words)
    if not np.issubdtype(words.dtype, np.integer) or words.ndim == 0 or words.shape[-1] != 3:
        raise ValueError(f"words: expected integer words of shape (..., 3), got {words.dtype} {words.shape}")
    modulus = 1 << settings.bits
    if words.size and (words.min() < 0 or words.max() >= modulus):
        raise ValueError(f"words: expected {settings.bits}-bit register words 0..{modulus - 1}")
    signed = np.where(words >= modulus // 2, words.astype(np.int64) - modulus, words)
    lowest, highest = _word_limits(settings)
    return signed * step_uT(settings), (signed <= lowest) | (signed >= highest)


class TLV493D:
    """One chip at its settings, as a design's twin reads the field with it (the sensor contract)."""

    reading = MAGNETIC

    def __init__(self, settings: TLV493DSettings) -> None:
        self.settings = settings

    def acquire(self, true: np.ndarray, rng: np.random.Generator | None = None) -> Acquisition:
        """Fields ``true`` (..., 3, tesla) as the registers hold them (``raw``: words 0 .. 2^bits - 1, two's
        complement) and as the host decodes them; with ``rng``, the data sheet's typical noise."""
        words = signed_words(true, self.settings, rng, NOISE_UT) % (1 << self.settings.bits)
        values, saturated = decode(self.settings, words)
        return Acquisition(values=values, raw=words, saturated=saturated)

    def to_dict(self) -> dict:
        return self.settings.to_dict()


SENSOR = SensorKind("tlv493d", MAGNETIC, 3, TLV493DSettings, widest=TLV493DSettings(), full_scale=full_scale_uT,
                    step=step_uT, decode=decode, raw_unit="counts", raw_bits=12, title="TLV493D", noise=noise_uT,
                    model=TLV493D, conversion_time=update_time_s)
