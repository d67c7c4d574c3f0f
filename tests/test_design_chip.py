"""A design names its chips: the twin reads its field with the registered sensor's model.

The second sensor is the example plug-in's Infineon TLV493D (examples/whisker), registered here as a
lab would install it. Its words, step, clip and noise are checked against its data sheet's figures by
hand (98 µT per word, 12-bit two's complement words, 0.1 mT rms noise, 3.3 kHz in fast mode); a
design that names no chip reads through the MLX90393 exactly as before.
"""

from __future__ import annotations

import dataclasses
import json
import pickle
import sys
from pathlib import Path

import numpy as np
import pytest
import scipy.stats
from typer.testing import CliRunner

from softtip._core.systems import register, systems, unregister
from softtip.design import model
from softtip.design.model import DesignError, load_design, shipped_design_path
from softtip.sensors.mlx90393 import MLX90393, SENSOR, MLX90393Settings
from softtip.twin import Readout

WHISKER = Path(__file__).resolve().parents[1] / "examples" / "whisker" / "src"
STEP_UT, NOISE_UT = 98.0, 100.0  # TLV493D-A1B6 data sheet: 98 µT/LSB, magnetic noise 0.1 mT rms (typ.)


@pytest.fixture(scope="module")
def tlv493d():
    """The example plug-in registered (unless it is installed): its sensor ``tlv493d``."""
    with pytest.MonkeyPatch.context() as patch:
        patch.syspath_prepend(str(WHISKER))
        from softtip_whisker import SYSTEM

        ours = SYSTEM.name not in systems()
        if ours:
            register(SYSTEM)
        yield
        if ours:
            unregister(SYSTEM.name)
            for name in [module for module in sys.modules if module.startswith("softtip_whisker")]:
                sys.modules.pop(name)


def tlv_design(tmp_path: Path, settings: str, positions: str = "[[0.0, 0.0, 0.8]]", name: str = "tlv") -> Path:
    """cylindrical-D read by TLV493D chips at ``settings`` (TOML lines of its [sensor] table)."""
    text = shipped_design_path("cylindrical-D").read_text()
    sensor = text.index("[sensor]")
    path = tmp_path / f"{name}.toml"
    path.write_text(text[:sensor] + f'[sensor]\npositions_mm = {positions}\nchip = "tlv493d"\n{settings}\n')
    return path


@pytest.mark.parametrize("bits, words, saturated", [
    # 12 bits: 50 mT / 98 µT = 510.2 -> 510; -0.1 mT -> -1.02 -> -1, word 4096 - 1; 210 mT -> 2142.9, clipped
    # at the top word 2047 (200.6 mT); -210 mT clipped at -2048, word 2048
    (12, [[510, 4095, 2047], [2048, 0, 0]], [[False, False, True], [True, False, False]]),
    # 8 bits: 16 x 98 = 1568 µT a word: 50 mT -> 31.9 -> 32; -0.1 mT -> -0.06 -> 0; 210 mT -> 133.9, the top
    # word 127; -210 mT -> -128, word 256 - 128
    (8, [[32, 0, 127], [128, 0, 0]], [[False, False, True], [True, False, False]]),
])
def test_a_tlv493d_design_reads_the_data_sheets_words_and_clip(tlv493d, tmp_path, bits, words, saturated):
    design = load_design(tlv_design(tmp_path, f'mode = "fast"\nbits = {bits}'))
    readout = Readout(design)
    assert design.chip_settings.kind.name == "tlv493d" and design.chip_settings.to_dict() == {"mode": "fast",
                                                                                            "bits": bits}
    fields = np.array([[[0.05, -1e-4, 0.21]], [[-0.21, 0.0, 0.0]]])  # T, (N = 2, S = 1, 3)
    _, raw = readout.read_field(fields, noise=False)
    np.testing.assert_array_equal(raw[:, 0], words)
    np.testing.assert_array_equal(readout.saturated(raw)[:, 0], saturated)


def test_a_tlv493d_designs_noise_is_the_data_sheets(tlv493d, tmp_path):
    readout = Readout(load_design(tlv_design(tmp_path, 'mode = "low-power"')))
    steady = np.broadcast_to(readout.rest_field + 1e-3, (20000, 1, 3))
    change, _ = readout.read_field(steady, rng=np.random.default_rng(4))
    # each change is a loaded reading less a baseline, both noisy and rounded to the step: a variance of
    # 2 (noise^2 + step^2 / 12) = (147 µT)^2; 20000 draws know a standard deviation to 0.5 %
    expected = np.sqrt(2 * (NOISE_UT**2 + STEP_UT**2 / 12))
    np.testing.assert_allclose(change[:, 0].std(axis=0), expected, rtol=5 / np.sqrt(2 * 20000))


@pytest.mark.slow  # a finite-element push: 10 s
def test_simulate_reads_a_tlv493d_design_with_its_noise_and_states_its_figures(tlv493d, tmp_path):
    from softtip.cli.main import app

    grid = [[x, y, 0.8] for x in (-4.5, -1.5, 1.5, 4.5) for y in (-4.5, -1.5, 1.5, 4.5)]
    design = tlv_design(tmp_path, 'mode = "fast"', positions=str(grid))
    result = CliRunner().invoke(app, ["simulate", "--design", str(design), "--angle", "45", "--json",
                                      "--mesh-size", "2.0"])
    assert result.exit_code == 0, result.output
    report = json.loads(result.stdout)
    chip = report["sensor_model"]
    assert chip["chip"] == "TLV493D" and chip["settings"] == {"mode": "fast", "bits": 12}
    assert chip["lsb_uT"] == [STEP_UT] * 3 and chip["noise_rms_uT"] == [NOISE_UT] * 3
    assert chip["max_rate_hz"] == pytest.approx(3300.0) and chip["conversion_time_ms"] == pytest.approx(1 / 3.3)
    # 48 axes, each the difference of two noisy readings rounded to 98 µT: in units of its standard deviation
    # the squared errors sum to a chi-square of 48 degrees of freedom, within its 0.1 % and 99.9 % quantiles
    sd = np.sqrt(2 * (NOISE_UT**2 + STEP_UT**2 / 12))
    errors = np.array([np.subtract(s["dB_uT"], s["dB_exact_uT"]) for s in report["sensors"]]) / sd
    assert scipy.stats.chi2.ppf(0.001, 48) < np.sum(errors**2) < scipy.stats.chi2.ppf(0.999, 48)
    assert all(0 <= word < 4096 for s in report["sensors"] for word in s["counts"])


def test_a_design_naming_no_chip_reads_through_the_mlx90393_as_before():
    design = load_design("cylindrical-A")
    settings = MLX90393Settings(gain_sel=7, res_xyz=(0, 0, 0), osr=0, dig_filt=2)  # its file's [sensor] table
    assert design.chip_settings.kind.name == "mlx90393" and design.chip_settings.values == settings
    readout, chip = Readout(design), MLX90393(settings)
    loaded = readout.rest_field + np.random.default_rng(2).normal(0.0, 2e-4, (50, 1, 3))
    change, raw = readout.read_field(loaded, rng=np.random.default_rng(3))
    draws = np.random.default_rng(3)
    read = chip.acquire(loaded, draws)
    baseline = chip.acquire(np.broadcast_to(readout.rest_field, loaded.shape), draws).values
    np.testing.assert_array_equal(change, read.values - baseline)
    np.testing.assert_array_equal(raw, read.raw)
    # a design goes to another process whole, its chips with it (pickle is the pools' transport, not a file's)
    sent = pickle.loads(pickle.dumps(design))
    assert sent.chip_settings == design.chip_settings and sent.spec == design.spec


@pytest.mark.parametrize("settings, message", [
    ('chip = "tlv493e"', "sensor.chip = 'tlv493e': expected a registered sensor (mlx90393, "),
    ('chip = "tlv493d"\nmode = "turbo"', "sensor.mode = 'turbo': expected one of fast, low-power, ultra-low-power"),
    ('chip = "tlv493d"\ngain_sel = 7', "sensor.gain_sel"),
    ("gain_sel = 9", "sensor.gain_sel = 9: expected an integer 0..7"),
])
def test_a_designs_chip_and_its_settings_are_refused_in_one_line_naming_the_file(tlv493d, tmp_path, settings,
                                                                                   message):
    text = shipped_design_path("cylindrical-A").read_text()
    path = tmp_path / "mistaken.toml"
    path.write_text(text[:text.index("[sensor]")] + f"[sensor]\n{settings}\n")
    with pytest.raises(DesignError) as refused:
        load_design(path)
    assert str(refused.value).startswith(f"{path}: ") and message in str(refused.value)
    assert "\n" not in str(refused.value)


def test_a_chip_without_a_model_of_the_field_is_refused_as_a_designs(tmp_path, monkeypatch):
    # a chip the toolkit knows only by its range and step (as the import and calibrate checks need): no twin
    bare = dataclasses.replace(SENSOR, name="bare-hall", title="bare Hall chip", model=None)
    monkeypatch.setitem(model.OWN_CHIPS, bare.name, bare)
    text = shipped_design_path("cylindrical-A").read_text()
    path = tmp_path / "bare.toml"
    path.write_text(text.replace("[sensor]\n", '[sensor]\nchip = "bare-hall"\n'))
    with pytest.raises(DesignError, match=r"bare.toml: sensor.chip = 'bare-hall': the bare Hall chip has no model of "
                                          r"its reading of flux density on x, y and z"):
        load_design(path)


@dataclasses.dataclass(frozen=True)
class PlainSettings:
    """A chip's settings as a plain dataclass, not a softtip schema: its own from_dict refuses in one line."""

    gain: int = 1

    @classmethod
    def from_dict(cls, table):
        if set(table) - {"gain"}:
            raise ValueError(f"expected gain, got {sorted(table)}")
        return cls(**table)

    def to_dict(self):
        return dataclasses.asdict(self)


def test_a_chip_whose_settings_are_not_a_softtip_schema_reads_them_with_its_own_refusals(tmp_path, monkeypatch):
    plain = dataclasses.replace(SENSOR, name="plain-hall", settings=PlainSettings, widest=PlainSettings())
    monkeypatch.setitem(model.OWN_CHIPS, plain.name, plain)
    text = shipped_design_path("cylindrical-A").read_text()
    sensor = text[:text.index("[sensor]")] + '[sensor]\nchip = "plain-hall"\n'
    (tmp_path / "plain.toml").write_text(sensor + "gain = 3\n")
    assert load_design(tmp_path / "plain.toml").chip_settings.values == PlainSettings(gain=3)
    (tmp_path / "mistaken.toml").write_text(sensor + "gian = 3\n")
    with pytest.raises(DesignError, match=r"^\S*mistaken.toml: sensor: expected gain, got \['gian'\]$"):
        load_design(tmp_path / "mistaken.toml")
