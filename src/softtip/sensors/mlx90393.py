"""Melexis MLX90393 3-axis Hall magnetometer: settings, datasheet facts, readout model.

The model turns the flux density at the sensitive point (tesla) into the raw
16-bit register words the chip returns for the configured GAIN_SEL, RES_XYZ,
OSR and DIG_FILT, and back again the way a host driver does. Everything is
vectorised over arrays of shape (..., 3) holding x, y, z.

Sources, cited by table in the comments below:
  [DS]  Melexis MLX90393 datasheet, rev. 006 (2020-01-08), document 3901090393.
  [AN]  Melexis MLX90393 application note "Getting Started" (2015), as quoted
        in the public issue trackers of the Adafruit and tedyapo drivers.
Temperature compensation (TCMP_EN = 1), which changes the output format, is
not modelled: TCMP_EN = 0 throughout.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Annotated, Any

import numpy as np
from numpy.typing import ArrayLike

from softtip._core.channels import MAGNETIC, Reading
from softtip._core.config import Flag, Refusal, choice, expect, from_numpy, integer, parse, schema
from softtip._core.units import UT_PER_T
from softtip.sensors.contract import Acquisition
from softtip.sensors.registry import SensorKind

# --------------------------------------------------------------------------
# Datasheet facts
# --------------------------------------------------------------------------


def _read_only(values: ArrayLike) -> np.ndarray:
    array = np.array(values, dtype=np.float64)
    array.setflags(write=False)
    return array


# [DS] section 15.1.4, Table 17: sensitivity in uT/LSB for HALLCONF = 0xC,
# rows GAIN_SEL 0..7, columns (XY, Z) for RES 0..3 as printed. Each RES step
# selects the next bit of the 19-bit ADC word, so an axis's entry is exactly
# twice the one of the previous RES up to the table's 3-decimal rounding. The
# printed XY entry GAIN_SEL 1 / RES 3 reads 4.840 (the Z value of the row
# above), a misprint: 2 x 2.403 = 4.806 is used.
_TABLE_17_HALLCONF_C_UT = np.array([
    #  RES 0 XY, Z   RES 1 XY, Z   RES 2 XY, Z   RES 3 XY, Z
    [0.751, 1.210, 1.502, 2.420, 3.004, 4.840, 6.009, 9.680],
    [0.601, 0.968, 1.202, 1.936, 2.403, 3.872, 4.806, 7.744],
    [0.451, 0.726, 0.901, 1.452, 1.803, 2.904, 3.605, 5.808],
    [0.376, 0.605, 0.751, 1.210, 1.502, 2.420, 3.004, 4.840],
    [0.300, 0.484, 0.601, 0.968, 1.202, 1.936, 2.403, 3.872],
    [0.250, 0.403, 0.501, 0.807, 1.001, 1.613, 2.003, 3.227],
    [0.200, 0.323, 0.401, 0.645, 0.801, 1.291, 1.602, 2.581],
    [0.150, 0.242, 0.300, 0.484, 0.601, 0.968, 1.202, 1.936],
])
SENSITIVITY_XY_HALLCONF_C_UT = _read_only(_TABLE_17_HALLCONF_C_UT[:, 0::2])
SENSITIVITY_Z_HALLCONF_C_UT = _read_only(_TABLE_17_HALLCONF_C_UT[:, 1::2])
# [DS] footnote to Table 17: "For HALLCONF = 0x0, the sensitivity scales with
# a factor 98/75" (0.150 -> 0.196 uT/LSB for XY at GAIN_SEL 7, RES 0).
HALLCONF_0_SENSITIVITY_FACTOR = 98.0 / 75.0
HALLCONF_DEFAULT = 0xC
SENSITIVITY_UT: dict[int, tuple[np.ndarray, np.ndarray]] = {
    0xC: (SENSITIVITY_XY_HALLCONF_C_UT, SENSITIVITY_Z_HALLCONF_C_UT),
    0x0: (
        _read_only(SENSITIVITY_XY_HALLCONF_C_UT * HALLCONF_0_SENSITIVITY_FACTOR),
        _read_only(SENSITIVITY_Z_HALLCONF_C_UT * HALLCONF_0_SENSITIVITY_FACTOR),
    ),
}

# [DS] Table 21, output data format with TCMP_EN = 0, indexed by RES 0..3.
# RES 0 and 1: signed 16-bit two's complement. RES 2 and 3: unsigned, the zero
# field sits at 2^15 (RES 2) and 2^14 (RES 3). The valid ranges of RES 2 and 3,
# +-22000 and +-11000 counts, are the same field span (88000 RES-0 counts);
# the model saturates the ADC there, and RES 0 and 1 saturate earlier, at the
# 16-bit limits of their signed word. Inferred from the table: the datasheet
# does not describe what the chip outputs beyond these ranges.
OUTPUT_ZERO_FIELD_COUNTS = (0, 0, 1 << 15, 1 << 14)
OUTPUT_LOWEST_COUNTS = (-(1 << 15), -(1 << 15), -22000, -11000)
OUTPUT_HIGHEST_COUNTS = ((1 << 15) - 1, (1 << 15) - 1, 22000, 11000)

# [DS] Table 8, timing of one single-measurement (SM) conversion:
#   T_CONV = T_STBY + T_ACTIVE + m * T_CONVM + T_CONVT (if T measured) + T_CONV_END
#   T_CONVM = 67 + 64 * 2^OSR * (2 + 2^DIG_FILT) us  per magnetic axis (m axes)
#   T_CONVT = 67 + 192 * 2^OSR2 us                     temperature
# The datasheet's own table of XYZ conversion times (reproduced in the
# Adafruit driver) equals T_STBY + T_ACTIVE + 3 * 64 * 2^OSR * (2 + 2^DIG_FILT),
# i.e. it leaves out the 67 us per axis and T_CONV_END; the full sum is used here.
STANDBY_TIME_S = 264e-6         # T_STBY: IDLE to STBY
ACTIVE_TIME_S = 432e-6          # T_ACTIVE: STBY to ACTIVE
CONVERSION_END_TIME_S = 120e-6  # T_CONV_END: end of analog active mode
AXIS_FIXED_TIME_S = 67e-6
AXIS_SAMPLE_TIME_S = 64e-6
TEMPERATURE_FIXED_TIME_S = 67e-6
TEMPERATURE_SAMPLE_TIME_S = 192e-6

# [DS] conversion-time table and [AN]: these (OSR, DIG_FILT) pairs are not
# permitted (HALLCONF = 0xC); they are refused for HALLCONF = 0x0 as well.
FORBIDDEN_OSR_DIG_FILT = frozenset({(0, 0), (0, 1), (1, 0)})

# RMS noise. The datasheet gives noise only as graphs (rev. 011, section 13.1,
# Figures 2 and 3: XY and Z RMS noise versus conversion time per OSR, GAIN_SEL 7,
# y axes 0-60 and 0-90 mGauss); no table. Published readings of those graphs
# (a magnetic-field logger built on the chip): OSR 3 / DIG_FILT 7 -> XY 0.2 uT,
# Z 0.4 uT; OSR 1 / DIG_FILT 7 -> 0.5-0.8 uT; OSR 0 / DIG_FILT 6 -> 0.9-1.2 uT.
# The model below reproduces all three within their reading spread:
#   * 0.25 uT RMS on XY at OSR 3 / DIG_FILT 7;
#   * noise proportional to 1/sqrt(averaging), averaging = 2^OSR * (2 + 2^DIG_FILT),
#     the sample count that also sets T_CONVM (white noise averaged);
#   * Z has the same noise in ADC counts as X and Y, so its noise in uT is
#     larger by the Z/XY sensitivity ratio (0.242 / 0.150 = 1.61; the graphs
#     show 4 vs 2 mGauss at the longest averaging);
#   * the gain scales signal and noise alike, so in uT the noise is fixed while
#     it is above the LSB; below the LSB, rounding to counts dominates;
#   * HALLCONF 0x0 is assumed to have the same noise in uT (the datasheet is silent).
NOISE_XY_REFERENCE_UT = 0.25
NOISE_REFERENCE_AVERAGING = (1 << 3) * (2 + (1 << 7))
NOISE_Z_TO_XY_RATIO = SENSITIVITY_Z_HALLCONF_C_UT[7, 0] / SENSITIVITY_XY_HALLCONF_C_UT[7, 0]

_UINT16_MODULUS = 1 << 16
_XYZ = np.arange(3)

# --------------------------------------------------------------------------
# Settings
# --------------------------------------------------------------------------


Resolution = integer(0, 3)
Resolutions = Annotated[tuple[Resolution, Resolution, Resolution], from_numpy, expect("3 integers, each 0..3")]
Hallconf = choice(0xC, 0x0, expected="0xC (12) or 0x0 (0)")


@schema(section="sensor")
class MLX90393Settings:
    """Register settings of one MLX90393 (TCMP_EN = 0).

    gain_sel: GAIN_SEL 0..7 (0 is the highest gain, the finest LSB is at 7).
    res_xyz: RES_X, RES_Y, RES_Z, each 0..3 (which 16 of the 19 ADC bits are output).
    osr, dig_filt: magnetic oversampling 0..3 and digital filter 0..7.
    osr2: temperature oversampling 0..3, used when temperature is measured.
    hallconf: HALLCONF 0xC (chip default) or 0x0.
    temperature: whether each conversion also measures the temperature.
    The defaults are the power-on register values except DIG_FILT, whose
    power-on value 0 is a forbidden combination with OSR 0; 2 is the fastest
    permitted filter.
    """

    gain_sel: integer(0, 7) = 7
    res_xyz: Resolutions = (0, 0, 0)
    osr: integer(0, 3) = 0
    dig_filt: integer(0, 7) = 2
    osr2: integer(0, 3) = 0
    hallconf: Hallconf = HALLCONF_DEFAULT
    temperature: Flag = False

    def __post_init__(self) -> None:
        if (self.osr, self.dig_filt) in FORBIDDEN_OSR_DIG_FILT:
            raise Refusal("dig_filt", f"not permitted with sensor.osr = {self.osr} by the datasheet; "
                          "use dig_filt >= 2 with osr 0 and dig_filt >= 1 with osr 1")

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> MLX90393Settings:
        """Settings from a mapping such as a parsed [sensor] table; unknown keys are refused."""
        return parse(cls, d, "", "sensor")

    def to_dict(self) -> dict[str, Any]:
        """Plain mapping (lists, ints, bool) that from_dict turns back into equal settings."""
        return {
            "gain_sel": self.gain_sel,
            "res_xyz": list(self.res_xyz),
            "osr": self.osr,
            "dig_filt": self.dig_filt,
            "osr2": self.osr2,
            "hallconf": self.hallconf,
            "temperature": self.temperature,
        }


# --------------------------------------------------------------------------
# Pure functions of the settings
# --------------------------------------------------------------------------


def lsb_uT(settings: MLX90393Settings) -> np.ndarray:
    """Microtesla per count for x, y, z, shape (3,)."""
    xy, z = SENSITIVITY_UT[settings.hallconf]
    res_x, res_y, res_z = settings.res_xyz
    gain = settings.gain_sel
    return np.array([xy[gain, res_x], xy[gain, res_y], z[gain, res_z]])


def _per_axis(settings: MLX90393Settings, by_res: tuple[int, ...]) -> np.ndarray:
    return np.array([by_res[res] for res in settings.res_xyz])


def full_scale_uT(settings: MLX90393Settings) -> np.ndarray:
    """Largest |B| in uT per axis (x, y, z) that is output without clipping, shape (3,)."""
    return _per_axis(settings, OUTPUT_HIGHEST_COUNTS) * lsb_uT(settings)


def averaging_count(settings: MLX90393Settings) -> int:
    """ADC samples averaged per magnetic axis: 2^OSR * (2 + 2^DIG_FILT)."""
    return (1 << settings.osr) * (2 + (1 << settings.dig_filt))


def conversion_time_s(settings: MLX90393Settings, axes: int = 3) -> float:
    """Single-measurement conversion time in seconds for `axes` magnetic axes (1..3).

    Includes the start-up from IDLE (T_STBY + T_ACTIVE), the end of the analog
    phase (T_CONV_END) and the temperature conversion when settings.temperature.
    Excludes the bus traffic of the SM and RM commands.
    """
    if isinstance(axes, (bool, np.bool_)) or not isinstance(axes, (int, np.integer)) or not 1 <= axes <= 3:
        raise ValueError(f"axes = {axes!r}: expected an integer 1..3")
    axis_time = AXIS_FIXED_TIME_S + AXIS_SAMPLE_TIME_S * averaging_count(settings)
    temperature_time = 0.0
    if settings.temperature:
        temperature_samples = 1 << settings.osr2
        temperature_time = (
            TEMPERATURE_FIXED_TIME_S + TEMPERATURE_SAMPLE_TIME_S * temperature_samples
        )
    return (
        STANDBY_TIME_S + ACTIVE_TIME_S + axes * axis_time + temperature_time + CONVERSION_END_TIME_S
    )


def max_output_rate_hz(settings: MLX90393Settings, axes: int = 3) -> float:
    """Readings per second in single-measurement mode: 1 / conversion_time_s."""
    return 1.0 / conversion_time_s(settings, axes)


def noise_rms_uT(settings: MLX90393Settings) -> np.ndarray:
    """RMS noise in uT per axis (x, y, z) before rounding to counts, shape (3,)."""
    xy = NOISE_XY_REFERENCE_UT * np.sqrt(NOISE_REFERENCE_AVERAGING / averaging_count(settings))
    return np.array([xy, xy, xy * NOISE_Z_TO_XY_RATIO])


# --------------------------------------------------------------------------
# Readout model
# --------------------------------------------------------------------------


class MLX90393:
    """One MLX90393: flux density to register words and back.

    Register words are returned as uint16, as read from the bus: RES 0/1 axes
    hold two's complement (a field of -1 count reads 0xFFFF), RES 2/3 axes hold
    the unsigned word with the zero field at 0x8000 / 0x4000.
    """

    def __init__(self, settings: MLX90393Settings | None = None) -> None:
        self._settings = MLX90393Settings() if settings is None else settings
        lsb = lsb_uT(self._settings)
        self._lsb_uT = lsb
        self._counts_per_tesla = UT_PER_T / lsb
        self._noise_counts = noise_rms_uT(self._settings) / lsb
        self._lowest = _per_axis(self._settings, OUTPUT_LOWEST_COUNTS).astype(np.float64)
        self._highest = _per_axis(self._settings, OUTPUT_HIGHEST_COUNTS).astype(np.float64)
        self._zero_field = _per_axis(self._settings, OUTPUT_ZERO_FIELD_COUNTS).astype(np.int32)
        self._twos_complement = np.array([res <= 1 for res in self._settings.res_xyz])
        self._word_tables: tuple[np.ndarray, np.ndarray] | None = None  # decode's lookup tables

    @property
    def settings(self) -> MLX90393Settings:
        return self._settings

    @property
    def reading(self) -> Reading:
        return MAGNETIC

    def acquire(self, b_tesla: ArrayLike, rng: np.random.Generator | None = None) -> Acquisition:
        """The sensor contract (:class:`~softtip.sensors.contract.Sensor`): register words for fields
        ``b_tesla`` (..., 3), with noise drawn from ``rng`` if given, decoded to µT as a host does."""
        counts = self.to_counts(b_tesla, rng=rng, noise=rng is not None)
        values, saturated = self.decode(counts)
        return Acquisition(values=values, raw=counts, saturated=saturated)

    def to_dict(self) -> dict:
        return self._settings.to_dict()

    def to_counts(self, b_tesla: ArrayLike, rng: np.random.Generator | None = None, noise: bool = True) -> np.ndarray:
        """Register words (uint16, shape of b_tesla) for fields b_tesla of shape (..., 3).

        Adds Gaussian noise of noise_rms_uT when noise is true (rng defaults to a
        fresh default_rng()), rounds to the nearest count and saturates at the
        output range of each axis's RES.
        """
        b = np.asarray(b_tesla, dtype=np.float64)
        _check_last_axis("b_tesla", b)
        counts = b * self._counts_per_tesla
        if noise:
            generator = np.random.default_rng() if rng is None else rng
            noise_counts = generator.standard_normal(b.shape)
            noise_counts *= self._noise_counts
            counts += noise_counts
        np.rint(counts, out=counts)
        np.clip(counts, self._lowest, self._highest, out=counts)
        if np.isnan(counts).any():
            raise ValueError("b_tesla contains NaN")
        words = counts.astype(np.int32)
        words += self._zero_field
        # int32 -> uint16 wraps modulo 2^16: negative RES 0/1 counts become two's complement.
        return words.astype(np.uint16)

    def counts_to_uT(self, counts: ArrayLike) -> np.ndarray:
        """Field in uT from register words of shape (..., 3), as a host driver decodes them."""
        return self._signed_counts(counts) * self._lsb_uT

    def read_uT(self, b_tesla: ArrayLike, rng: np.random.Generator | None = None, noise: bool = True) -> np.ndarray:
        """What the host reads in uT for fields b_tesla (..., 3): counts_to_uT(to_counts(...))."""
        return self.counts_to_uT(self.to_counts(b_tesla, rng=rng, noise=noise))

    def saturated(self, counts: ArrayLike) -> np.ndarray:
        """Boolean mask, shape of counts, of words at the saturation limit of their axis."""
        return self.decode(counts)[1]

    def decode(self, counts: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        """Both at once, for a host reading every frame: (field in uT, saturated mask).

        uint16 words, as a driver has them, are looked up in a table of all 2^16 words per
        axis (built from the same conversion on first use): two array operations instead of
        a dozen, which is what a frame costs when it wakes a reader thread with cold caches.
        """
        if isinstance(counts, np.ndarray) and counts.dtype == np.uint16:
            _check_last_axis("counts", counts)
            if self._word_tables is None:
                every_word = np.repeat(np.arange(_UINT16_MODULUS, dtype=np.uint16)[:, None], 3, axis=1)
                self._word_tables = self._convert(self._signed_counts(every_word))
            field_table, saturated_table = self._word_tables
            return field_table[counts, _XYZ], saturated_table[counts, _XYZ]
        return self._convert(self._signed_counts(counts))

    def _convert(self, signed: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return signed * self._lsb_uT, (signed <= self._lowest) | (signed >= self._highest)

    def _signed_counts(self, counts: ArrayLike) -> np.ndarray:
        words = np.asarray(counts)
        _check_last_axis("counts", words)
        if not np.issubdtype(words.dtype, np.integer):
            raise ValueError(f"counts has dtype {words.dtype}: expected integer register words")
        if words.dtype != np.uint16 and words.size:
            if words.min() < 0 or words.max() >= _UINT16_MODULUS:
                raise ValueError("counts outside 0..65535: expected 16-bit register words")
        signed = words.astype(np.int32)
        signed -= self._zero_field
        signed -= _UINT16_MODULUS * ((signed >= 1 << 15) & self._twos_complement)
        return signed


def _check_last_axis(name: str, array: np.ndarray) -> None:
    if array.ndim == 0 or array.shape[-1] != 3:
        raise ValueError(f"{name} has shape {array.shape}: expected (..., 3) for x, y, z")


def decode_words(settings: MLX90393Settings, words: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
    """Register words (..., 3) at ``settings`` as (field in uT, saturated), as a host decodes them."""
    return MLX90393(settings).decode(words)


# as the toolkit's checks know it (softtip.sensors.registry), declared by the systems that use it; its
# functions are the module's (a design that holds it can be sent to another process)
SENSOR = SensorKind("mlx90393", MAGNETIC, 3, MLX90393Settings, widest=MLX90393Settings(gain_sel=0, res_xyz=(3, 3, 3)),
                    full_scale=full_scale_uT, step=lsb_uT, decode=decode_words, raw_unit="counts", raw_bits=16,
                    title="MLX90393", noise=noise_rms_uT, model=MLX90393, conversion_time=conversion_time_s)
