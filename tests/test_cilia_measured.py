"""``softtip cilia fit CURVE.csv``: a researcher's curve read from a table (grams, a tare) and fitted with both
models; a curve made by the publication's model at known moment and diameter is recovered by it, within
its intervals."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest
import typer
from typer.testing import CliRunner

from softtip.cli.common import user_errors
from softtip.systems.cilia.bench import curve_from_csv
from softtip.systems.cilia.layout import DieError, read_die, uniform_clamped
from softtip.systems.cilia.measured import MODELS
from softtip.systems.cilia.model import CiliaModel

G = 9.80665e-3  # N per gram on a balance


@pytest.fixture(scope="module")
def balance_table(tmp_path_factory):
    """A curve of the publication's model at its published fit (0.9 memu, 280 µm), 1 % noise, as a balance
    logs it: grams, and the sensor's whole voltage with its unloaded readings first."""
    die = read_die()
    truth = CiliaModel(uniform_clamped(die.with_pillars(replace(die.pillars, moment=0.9e-6).with_diameter(280e-6))))
    forces = np.linspace(0.0, 26e-3, 13)
    curve = truth.curve(forces)
    rng = np.random.default_rng(7)
    volts = curve.volts + rng.normal(0.0, 0.01 * np.abs(curve.change).max(), forces.size)
    path = tmp_path_factory.mktemp("curve") / "balance.csv"
    rows = [f"{f / G:.6f},{v:.9f}" for f, v in zip(forces, volts)]
    path.write_text("grams,volts\n" + "\n".join(rows) + "\n", encoding="utf-8")
    return path, forces, volts


def test_a_table_in_grams_is_read_as_newtons_and_tared_at_zero_force(balance_table):
    path, forces, volts = balance_table
    curve = curve_from_csv(path, "grams", "volts", "g", "X", tare=True)
    np.testing.assert_allclose(curve.force, forces, rtol=0, atol=1e-8)  # grams written to 1 µg
    np.testing.assert_allclose(curve.change, volts - volts[0], rtol=0, atol=1e-9)
    with pytest.raises(ValueError, match="balance.csv: no column 'force_N'"):
        curve_from_csv(path, "force_N", "volts", "N", "X", tare=False)
    untared = path.with_name("loaded.csv")
    untared.write_text("grams,volts\n1.0,18.7\n2.0,18.69\n3.0,18.68\n")
    with pytest.raises(DieError, match="no row at zero force in 'grams'"):
        curve_from_csv(untared, "grams", "volts", "g", "X", tare=True)


def test_the_command_recovers_the_publications_fit_with_its_model(balance_table, tmp_path):
    from softtip.systems.cilia.commands import fit_cilia

    path, _, _ = balance_table
    app = typer.Typer()
    app.command()(user_errors(fit_cilia))
    plot = tmp_path / "fits.png"
    ran = CliRunner().invoke(app, [str(path), "--force-column", "grams", "--force-unit", "g", "--voltage-column",
                                   "volts", "--tare", "--plot", str(plot), "--json"])
    assert ran.exit_code == 0, ran.output
    report = json.loads(ran.stdout)
    published, own = (report["fits"][name] for name in MODELS)
    # the truth, 0.9 memu and 280 µm, inside the publication's model's 95 % intervals, which are narrow
    low, high = published["moment_interval_memu"]
    assert low < 0.9 < high and high / low < 1.2
    low, high = published["diameter_interval_um"]
    assert low < 280.0 < high and high / low < 1.1
    assert not published["at_bound"] and plot.stat().st_size > 0
    # softtip's tapered model on its film reads the same curve with a thinner tip (its base is 1.6 x wider)
    assert own["diameter_um"] < 0.9 * published["diameter_um"]
    refused = CliRunner().invoke(app, [str(path), "--force-unit", "kg"])
    assert refused.exit_code == 2 and "--force-unit = 'kg': expected one of N, mN, g" in refused.output
