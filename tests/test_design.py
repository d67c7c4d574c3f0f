"""Design files: the shipped designs, every validation rule, and the mesh cache."""

from __future__ import annotations

import copy
import math
import tomllib

import numpy as np
import pytest

from softtip.design.model import (
    MM,
    DesignError,
    design_from_dict,
    load_design,
    polarization_from_surface_field,
    shipped_design_path,
    shipped_designs,
)
from softtip.magnetics import axial_cylinder_field


def spec(name: str) -> dict:
    return tomllib.loads(shipped_design_path(name).read_text())


def with_value(base: dict, dotted: str, value) -> dict:
    out = copy.deepcopy(base)
    section, _, key = dotted.partition(".")
    if key:
        out[section][key] = value
    else:
        out[section] = value
    return out


def test_the_published_designs_are_shipped():
    # softtip's own, beside those of any system installed with it
    assert {"cylindrical-A", "cylindrical-B", "cylindrical-C", "cylindrical-D", "rectangular"} <= set(shipped_designs())
    published = {"A": (9.0, 5.5), "B": (10.0, 6.5), "C": (8.5, 4.5), "D": (10.0, 4.5)}
    for letter, (p1, p2) in published.items():
        design = load_design(f"cylindrical-{letter}")
        assert design.spec["cavity"]["radius_mm"] == p1
        radii = [math.hypot(m.center[0], m.center[1]) for m in design.magnets]
        np.testing.assert_allclose(radii, p2 * MM)
        assert len(design.magnets) == 4 and len(design.sensor_positions) == 1
        assert design.material.youngs_modulus == 0.59e6 and design.material.poisson_ratio == 0.48


def test_generation_one_size_rationale_holds():
    # diameter >= 0.2 x board length (125 mm) and height >= 0.1 x board width (90 mm)
    design = load_design("cylindrical-A")
    assert design.spec["body"]["diameter_mm"] >= 0.2 * 125
    assert design.spec["body"]["height_mm"] >= 0.1 * 90


def test_rectangular_design_has_two_sensors_under_four_magnets():
    design = load_design("rectangular")
    assert min(design.spec["body"]["width_mm"], design.spec["body"]["length_mm"]) == 35.0
    assert len(design.magnets) == 4 and len(design.sensor_positions) == 2
    assert all(m.diameter == pytest.approx(4 * MM) and m.height == pytest.approx(2 * MM) for m in design.magnets)


def test_surface_field_conversion_reproduces_that_field_at_the_face():
    polarization = polarization_from_surface_field(0.330, 4 * MM, 2 * MM)
    face_centre = axial_cylinder_field([0.0, 0.0, 1 * MM], 2 * MM, 2 * MM, polarization)
    assert face_centre[2] == pytest.approx(0.330, rel=1e-9)
    assert load_design("rectangular").magnets[0].polarization == pytest.approx(polarization)


@pytest.mark.parametrize(
    ("name", "dotted", "value", "message"),
    [
        ("cylindrical-A", "magnets.circle_radius_mm", 1.2, "magnets overlap"),
        ("cylindrical-A", "magnets.circle_radius_mm", 11.8, "side surface"),
        ("cylindrical-A", "magnets.circle_radius_mm", 11.2, "filleted top edge"),
        ("cylindrical-A", "magnets.depth_mm", 3.0, "cut into the cavity"),
        ("cylindrical-A", "magnets.depth_mm", 0.0, "positive"),
        ("cylindrical-A", "magnets.depth_mm", 8.0, "reach the base"),
        ("cylindrical-A", "cavity.radius_mm", 12.5, "narrower than the body"),
        ("cylindrical-A", "cavity.height_mm", 9.0, "lower than the body"),
        ("cylindrical-A", "body.diameter_mm", -25.0, "positive"),
        ("cylindrical-A", "body.height_mm", "tall", "expected a number"),
        ("cylindrical-A", "body.fillet_mm", 9.5, "fillet"),
        ("cylindrical-A", "body.poisson_ratio", 0.5, "0 < nu < 0.5"),
        ("cylindrical-A", "magnets.count", 0, "positive integer"),
        ("cylindrical-A", "magnets.polarization_T", 3.0, "1.6 T"),
        ("cylindrical-A", "sensor.positions_mm", [[0.0, 0.0, 6.0]], "inside the cavity"),
        ("cylindrical-A", "sensor.positions_mm", "middle", "list of [x, y, z]"),
        ("rectangular", "magnets.pitch_x_mm", 3.0, "overlap"),
        ("rectangular", "magnets.pitch_y_mm", 38.0, "side surface"),
        ("rectangular", "cavity.width_mm", 36.0, "smaller than the body"),
        ("rectangular", "magnets.depth_mm", 5.0, "cut into the cavity"),
        ("cylindrical-A", "body.youngs_modulus_Pa", 1e300, "expected 1e3 <= E <= 1e8 Pa"),
        ("cylindrical-A", "body.youngs_modulus_Pa", 10.0, "expected 1e3 <= E <= 1e8 Pa"),
        ("cylindrical-A", "body.density_kg_m3", 1e9, "expected 100 <= rho <= 20000 kg/m3"),
        # J = 2 B L^-1 sqrt(R^2 + L^2) = 2 * 0.9 T * sqrt(2^2 + 2^2) / 2 = 2.55 T for the 4 x 2 mm magnets
        ("rectangular", "magnets.surface_field_T", 0.9, "a polarisation of 2.55 T: expected at most 1.6 T"),
    ],
)
def test_impossible_designs_are_refused_with_one_line_naming_the_parameter(name, dotted, value, message):
    with pytest.raises(DesignError) as error:
        design_from_dict(with_value(spec(name), dotted, value), source=f"{name}.toml")
    text = str(error.value)
    assert message in text
    assert dotted.split(".")[-1] in text
    assert "\n" not in text


@pytest.mark.parametrize(
    ("change", "message"),
    [
        (lambda s: s.update(colour="red"), "colour: unknown key"),
        (lambda s: s["magnets"].update(grade="N52"), "magnets.grade: unknown key"),
        (lambda s: s.update(kind="spherical"), "kind = 'spherical'"),
        (lambda s: s["magnets"].update(surface_field_T=0.3), "not both"),
    ],
)
def test_unknown_or_conflicting_keys_are_refused(change, message):
    data = spec("cylindrical-A")
    change(data)
    with pytest.raises(DesignError, match=message):
        design_from_dict(data)


def test_bad_sensor_settings_are_refused_when_the_design_is_read():
    with pytest.raises(DesignError, match=r"^mine.toml: sensor.gain_sel = 9: expected an integer 0..7$"):
        design_from_dict(with_value(spec("cylindrical-A"), "sensor.gain_sel", 9), source="mine.toml")
    with pytest.raises(DesignError, match=r"^mine.toml: sensor.dig_filt = 0: not permitted with sensor.osr = 0 by the datasheet"):
        design_from_dict(with_value(spec("cylindrical-A"), "sensor.dig_filt", 0), source="mine.toml")


def test_with_params_revalidates_and_rejects_unknown_parameters():
    design = load_design("cylindrical-A")
    changed = design.with_params(**{"cavity.radius_mm": 8.0, "magnets.circle_radius_mm": 6.5})
    assert changed.spec["cavity"]["radius_mm"] == 8.0
    assert math.hypot(*changed.magnets[0].center[:2]) == pytest.approx(6.5 * MM)
    with pytest.raises(DesignError, match="unknown design parameter"):
        design.with_params(**{"cavity.depth_mm": 1.0})
    with pytest.raises(DesignError, match="overlap"):
        design.with_params(**{"magnets.circle_radius_mm": 1.0})


def test_missing_and_malformed_files_are_refused(tmp_path):
    with pytest.raises(DesignError, match="neither a file nor a shipped design"):
        load_design("cylindrical-Z")
    broken = tmp_path / "broken.toml"
    broken.write_text("kind = 'cylindrical'\n[body\n")
    with pytest.raises(DesignError, match="not valid TOML"):
        load_design(broken)


def test_meshes_are_cached_by_geometry(tmp_path, monkeypatch):
    from softtip.mechanics.mesh import mesh_design, mesh_key

    monkeypatch.setenv("SOFTTIP_CACHE_DIR", str(tmp_path))
    design = load_design("cylindrical-B")
    first = mesh_design(design, 3 * MM)
    assert len(list((tmp_path / "meshes").glob("*.npz"))) == 1
    again = mesh_design(design, 3 * MM)
    np.testing.assert_array_equal(first.tets, again.tets)
    # a material change keeps the geometry and the mesh; a geometry change does not
    stiffer = design_from_dict(with_value(spec("cylindrical-B"), "body.youngs_modulus_Pa", 1e6))
    assert mesh_key(stiffer, 3 * MM, 10) == mesh_key(design, 3 * MM, 10)
    assert mesh_key(design.with_params(**{"cavity.radius_mm": 9.5}), 3 * MM, 10) != mesh_key(design, 3 * MM, 10)
    # a damaged cache file is rebuilt, not trusted
    cached = next((tmp_path / "meshes").glob("*.npz"))
    cached.write_bytes(b"not a mesh")
    rebuilt = mesh_design(design, 3 * MM)
    assert rebuilt.tets.shape == first.tets.shape


def test_mesh_has_every_boundary_and_magnet_holes_of_the_right_size():
    from softtip.mechanics.mesh import mesh_design

    design = load_design("cylindrical-D")
    mesh = mesh_design(design, 1 * MM)
    assert {"base", "cavity", "outer", "magnet0", "magnet1", "magnet2", "magnet3"} <= set(mesh.boundaries)
    for i, magnet in enumerate(design.magnets):
        points = mesh.points[np.unique(mesh.boundaries[f"magnet{i}"])] - np.array(magnet.center)
        assert np.hypot(points[:, 0], points[:, 1]).max() == pytest.approx(magnet.diameter / 2, rel=1e-6)
        assert np.abs(points[:, 2]).max() == pytest.approx(magnet.height / 2, rel=1e-6)
    # volume of the body = cylinder - cavity - magnets - the fillet's missing ring
    a, b, c, d = (mesh.points[mesh.tets[k]] for k in range(4))
    volume = np.einsum("ij,ij->i", np.cross(b - a, c - a), d - a).sum() / 6
    r, h, f = 12.5 * MM, 9 * MM, 3 * MM
    # Pappus: the spandrel (1 - pi/4) f^2 has its centroid f (10 - 3 pi) / (12 - 3 pi) in from the corner
    fillet_ring = (1 - math.pi / 4) * f**2 * 2 * math.pi * (r - f * (10 - 3 * math.pi) / (12 - 3 * math.pi))
    magnets = sum(math.pi * (m.diameter / 2) ** 2 * m.height for m in design.magnets)
    expected = math.pi * r**2 * h - math.pi * (10 * MM) ** 2 * 5 * MM - magnets - fillet_ring
    assert volume == pytest.approx(expected, rel=3e-3)  # facets of curved faces; the magnets are 0.7 %
