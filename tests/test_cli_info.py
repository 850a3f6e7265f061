"""`taichi-frac info`: JSON keys, Table 1 numbers, primitive specs, files and errors."""

import json
import re

import pytest
import trimesh

from taichi_frac.cli import main


@pytest.fixture(autouse=True)
def private_cache(tmp_path, monkeypatch):
    monkeypatch.setenv("TAICHI_FRAC_CACHE", str(tmp_path / "cache"))


def _json(capsys, argv):
    assert main(argv) == 0
    return json.loads(capsys.readouterr().out)


def test_json_for_the_paper_ring(capsys):
    data = _json(capsys, ["info", "torus", "--json"])
    for key in ("physics_particles", "surface_particles", "boundary_particles", "tets", "volume_error",
                "min_dihedral_deg", "mass", "center_of_mass", "inertia", "timings"):
        assert key in data
    assert data["tets"] == data["physics_particles"]
    assert abs(data["physics_particles"] / 5000 - 1) < 0.1
    assert abs(data["volume_error"]) < 1e-3
    assert data["surface_particles"] < data["physics_particles"]
    assert data["boundary_particles"] <= data["surface_particles"] / 3  # n = 4 groups
    assert data["mass"] == pytest.approx(2400 * 2 * 3.141592653589793**2 * 0.1 * 0.025**2, rel=1e-3)


def test_spec_parameters_particles_and_group_size(capsys):
    a = _json(capsys, ["info", "torus:major=0.2,minor=0.05", "--particles", "1500", "--group-size", "2", "--json"])
    assert abs(a["tets"] / 1500 - 1) < 0.15
    assert a["boundary_particles"] >= a["surface_particles"] / 2
    assert a["mass"] == pytest.approx(2400 * 2 * 3.141592653589793**2 * 0.2 * 0.05**2, rel=1e-3)


def test_file_with_units_and_table_output(tmp_path, capsys):
    path = tmp_path / "brick.stl"
    trimesh.creation.box((100.0, 50.0, 20.0)).export(str(path))
    data = _json(capsys, ["info", str(path), "--units", "mm", "--particles", "600", "--json"])
    assert data["tet_volume"] == pytest.approx(0.1 * 0.05 * 0.02, rel=1e-9)
    # The particle spacing is the tets' mean V^(1/3): at most the cube root of the mean volume
    # (Jensen, equal only when every tet has the same volume), and near it for a quality mesh.
    mean_root = (data["tet_volume"] / data["tets"]) ** (1.0 / 3.0)
    assert 0.75 * mean_root < data["particle_spacing"] <= mean_root
    assert main(["info", str(path), "--units", "mm", "--particles", "600"]) == 0
    out = capsys.readouterr().out
    assert "physics particles (tets)" in out and "boundary particles" in out and "min dihedral angle" in out
    assert re.search(rf"particle spacing +{data['particle_spacing']:.3g} m \(mean tet V\^\(1/3\)", out)


def test_errors_exit_2_with_the_message(tmp_path, capsys):
    path = tmp_path / "open.obj"
    path.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 3 2\nf 1 2 4\nf 1 4 3\n")
    assert main(["info", str(path)]) == 2
    assert "'open.obj' is not closed: 1 boundary loop, 3 open edges" in capsys.readouterr().err
    assert main(["info", "torus:radius=1"]) == 2
    assert "unknown parameter 'radius=1'" in capsys.readouterr().err
    assert main(["info", str(path), "--repair", "--json", "--particles", "200"]) == 0
    assert json.loads(capsys.readouterr().out)["repair_steps"]


def test_help_lists_the_options(capsys):
    with pytest.raises(SystemExit):
        main(["info", "--help"])
    out = capsys.readouterr().out
    for flag in ("--particles", "--json", "--units", "--repair", "--group-size", "torus:major="):
        assert flag in out
