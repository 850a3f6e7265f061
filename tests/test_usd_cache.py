"""The USD cache writer (taichi_frac.io.cache) checked through pxr's own queries, independent of
the add-on, and the add-on's bpy-free reader checked against closed-form motion."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest
from pxr import Usd, UsdGeom, UsdShade

sys.path.insert(0, str(Path(__file__).resolve().parent / "blender"))
import synthetic  # noqa: E402
import write_synthetic  # noqa: E402
from addon_loader import addon_module  # noqa: E402

from taichi_frac.io import CacheWriter, schema  # noqa: E402
from taichi_frac.io.cache import check_cache  # noqa: E402
from taichi_frac.options import LOOKS  # noqa: E402

FRAMES = range(synthetic.START_FRAME, synthetic.END_FRAME + 1)
# Y-up stage -> Z-up world: (x, y, z) -> (x, -z, y).
Y_TO_Z = np.array([[1.0, 0, 0], [0, 0, -1.0], [0, 1.0, 0]])


@pytest.fixture(scope="module")
def caches(tmp_path_factory):
    folder = tmp_path_factory.mktemp("usd")
    z_up = folder / "z_up.usdc"
    y_cm = folder / "y_up_cm.usda"
    write_synthetic.write(z_up)
    write_synthetic.write(y_cm, up_axis="Y", meters_per_unit=0.01)
    return {"z": z_up, "y_cm": y_cm}


def fragment_prim(stage, name):
    return stage.GetPrimAtPath(f"{schema.FRAGMENTS_SCOPE}/{name}")


def test_cache_passes_usd_validators(caches):
    for path in caches.values():
        assert check_cache(path) == []


def test_checker_reports_a_noncompliant_stage(tmp_path):
    # The checker must be able to fail: a mesh on a stage without upAxis/metersPerUnit/defaultPrim.
    stage = Usd.Stage.CreateNew(str(tmp_path / "bad.usda"))
    UsdGeom.Mesh.Define(stage, "/m")
    stage.Save()
    errors = check_cache(tmp_path / "bad.usda")
    assert any("MissingUpAxis" in e for e in errors) and any("MissingDefaultPrim" in e for e in errors)


def test_stage_metadata(caches):
    stage = Usd.Stage.Open(str(caches["z"]))
    assert UsdGeom.GetStageUpAxis(stage) == "Z"
    assert UsdGeom.GetStageMetersPerUnit(stage) == 1.0
    assert stage.GetTimeCodesPerSecond() == synthetic.FPS
    assert stage.GetStartTimeCode() == synthetic.START_FRAME
    assert stage.GetEndTimeCode() == synthetic.END_FRAME
    data = stage.GetRootLayer().customLayerData[schema.LAYER_DATA_KEY]
    assert data[schema.KEY_COMPLETE] and data[schema.KEY_LAST_FRAME] == synthetic.END_FRAME
    assert data[schema.KEY_VERSION] == schema.SCHEMA_VERSION
    stage = Usd.Stage.Open(str(caches["y_cm"]))
    assert UsdGeom.GetStageUpAxis(stage) == "Y" and UsdGeom.GetStageMetersPerUnit(stage) == 0.01


@pytest.mark.parametrize("which", ["z", "y_cm"])
def test_world_pose_and_visibility_every_frame(caches, which):
    """Body-frame vertices through USD's own world transform land where the closed form puts them
    (after undoing the stage's axis and unit); visibility follows birth and death."""
    stage = Usd.Stage.Open(str(caches[which]))
    meters = UsdGeom.GetStageMetersPerUnit(stage)
    turn = Y_TO_Z if UsdGeom.GetStageUpAxis(stage) == "Y" else np.eye(3)
    for name, (birth, death, _, half) in synthetic.FRAGMENTS.items():
        prim = fragment_prim(stage, name)
        points = np.asarray(UsdGeom.Mesh(prim).GetPointsAttr().Get(), dtype=np.float64)
        body, _ = synthetic.box_mesh(half)
        np.testing.assert_allclose(points * meters, body, atol=1e-6)  # float32 points
        for frame in FRAMES:
            visible = UsdGeom.Imageable(prim).ComputeVisibility(Usd.TimeCode(frame)) != UsdGeom.Tokens.invisible
            assert visible == synthetic.alive(name, frame), (name, frame)
            if not visible:
                continue
            m = np.asarray(UsdGeom.Xformable(prim).ComputeLocalToWorldTransform(Usd.TimeCode(frame)))
            world = ((np.c_[points, np.ones(len(points))] @ m)[:, :3] @ turn.T) * meters
            expected = (synthetic.world_matrix(*synthetic.pose(name, frame)) @ np.c_[body, np.ones(len(body))].T).T
            np.testing.assert_allclose(world, expected[:, :3], atol=1e-6)


def test_subsets_materials_and_custom_attributes(caches):
    stage = Usd.Stage.Open(str(caches["z"]))
    for name, (birth, death, parent, half) in synthetic.FRAGMENTS.items():
        prim = fragment_prim(stage, name)
        binding = UsdShade.MaterialBindingAPI(prim)
        subsets = {s.GetPrim().GetName(): s for s in binding.GetMaterialBindSubsets()}
        assert set(subsets) == {schema.OUTER_SUBSET, schema.INNER_SUBSET}
        assert binding.GetMaterialBindSubsetsFamilyType() == UsdGeom.Tokens.partition
        inner = sorted(subsets[schema.INNER_SUBSET].GetIndicesAttr().Get())
        outer = sorted(subsets[schema.OUTER_SUBSET].GetIndicesAttr().Get())
        assert inner == synthetic.INNER_FACES[name]
        assert sorted(inner + outer) == list(range(12))
        for subset_name, subset in subsets.items():
            material = UsdShade.MaterialBindingAPI(subset.GetPrim()).ComputeBoundMaterial()[0]
            # Every piece shares its root body's materials.
            assert material.GetPath() == f"{schema.MATERIALS_SCOPE}/slab/{subset_name}"
            shader = material.ComputeSurfaceSource()[0]
            assert shader.GetIdAttr().Get() == "UsdPreviewSurface"
        assert prim.GetAttribute(schema.ATTR_BIRTH_FRAME).Get() == birth
        assert prim.GetAttribute(schema.ATTR_DEATH_FRAME).Get() == (-1 if death is None else death)
        assert prim.GetAttribute(schema.ATTR_PEAK_STRESS).Get() == synthetic.peak_stress(name)
        stress = UsdGeom.PrimvarsAPI(prim).GetPrimvar(schema.PRIMVAR_FACE_STRESS)
        assert stress.GetInterpolation() == UsdGeom.Tokens.uniform
        np.testing.assert_allclose(stress.Get(), synthetic.face_stress(name, 12), rtol=1e-6)
        if parent is None:
            assert not prim.GetRelationship(schema.ATTR_PARENT)
            assert not prim.GetAttribute(schema.ATTR_IMPACT_FORCE)
        else:
            assert prim.GetRelationship(schema.ATTR_PARENT).GetTargets() == [fragment_prim(stage, parent).GetPath()]
            np.testing.assert_allclose(prim.GetAttribute(schema.ATTR_IMPACT_FORCE).Get(), synthetic.IMPACT["force"])
            np.testing.assert_allclose(prim.GetAttribute(schema.ATTR_IMPACT_POINT).Get(), synthetic.IMPACT["point"])


def test_normals_and_uvs_kept_on_outer_faces_only(tmp_path):
    vertices, faces = synthetic.box_mesh((0.5, 0.5, 0.5))
    inner = np.zeros(12, dtype=bool)
    inner[[0, 1]] = True
    smooth = vertices / np.linalg.norm(vertices, axis=1, keepdims=True)  # per-vertex input normals
    uvs = np.stack([np.arange(8) / 8.0, np.arange(8)[::-1] / 8.0], axis=1)
    corner_uvs = uvs[faces].copy()
    corner_uvs[5] = np.nan  # face 5 has no input UVs
    path = tmp_path / "n.usda"
    with CacheWriter(path, fps=30) as w:
        w.add_fragment("piece", vertices, faces, inner, 0, normals=smooth, uvs=corner_uvs)
        w.add_fragment("piece", vertices, faces, inner, 0)  # same name: gets a unique prim name
    stage = Usd.Stage.Open(str(path))
    names = [p.GetName() for p in stage.GetPrimAtPath(schema.FRAGMENTS_SCOPE).GetChildren()]
    assert names == ["piece", "piece_1"]
    mesh = UsdGeom.Mesh(stage.GetPrimAtPath(f"{schema.FRAGMENTS_SCOPE}/piece"))
    assert mesh.GetNormalsInterpolation() == UsdGeom.Tokens.faceVarying
    normals = np.asarray(mesh.GetNormalsAttr().Get()).reshape(12, 3, 3)
    tri = vertices[faces]
    flat = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    flat /= np.linalg.norm(flat, axis=1, keepdims=True)
    np.testing.assert_allclose(normals[:2], np.repeat(flat[:2, None], 3, axis=1), atol=1e-6)  # crack: flat
    np.testing.assert_allclose(normals[2:], smooth[faces[2:]], atol=1e-6)  # original surface: input
    st = UsdGeom.PrimvarsAPI(mesh).GetPrimvar(schema.PRIMVAR_UV)
    assert st.GetInterpolation() == UsdGeom.Tokens.faceVarying
    st = np.asarray(st.Get()).reshape(12, 3, 2)
    np.testing.assert_allclose(st[2:5], uvs[faces[2:5]], atol=1e-7)
    np.testing.assert_allclose(st[6:], uvs[faces[6:]], atol=1e-7)
    assert not np.allclose(st[0], uvs[faces[0]])  # crack faces get their own projection
    # The second piece had no normals: every face flat.
    plain = UsdGeom.Mesh(stage.GetPrimAtPath(f"{schema.FRAGMENTS_SCOPE}/piece_1"))
    np.testing.assert_allclose(np.asarray(plain.GetNormalsAttr().Get()).reshape(12, 3, 3),
                               np.repeat(flat[:, None], 3, axis=1), atol=1e-6)
    assert check_cache(path) == []


def test_schema_copy_in_addon_matches():
    addon_schema = addon_module("schema")
    mine = {k: v for k, v in vars(schema).items() if k.isupper()}
    theirs = {k: v for k, v in vars(addon_schema).items() if k.isupper()}
    assert mine == theirs


@pytest.mark.parametrize("which", ["z", "y_cm"])
def test_addon_reader_recovers_closed_form_motion(caches, which):
    """The add-on's reader (pxr + numpy, no bpy) returns Z-up metres whatever the stage says."""
    cache = addon_module("reader").read_cache(caches[which])
    assert (cache.fps, cache.start_frame, cache.end_frame) == (synthetic.FPS, synthetic.START_FRAME, synthetic.END_FRAME)
    roots = [name for name, (_, _, parent, _) in synthetic.FRAGMENTS.items() if parent is None]
    assert [m.name for m in cache.materials] == [f"{r}_{s}" for r in roots for s in (schema.OUTER_SUBSET, schema.INNER_SUBSET)]
    by_name = {f.name: f for f in cache.fragments}
    assert sorted(by_name) == sorted(synthetic.FRAGMENTS)
    for name, fragment in by_name.items():
        birth, death, parent, half = synthetic.FRAGMENTS[name]
        np.testing.assert_allclose(fragment.vertices, synthetic.box_mesh(half)[0], atol=1e-6)
        assert sorted(np.nonzero(fragment.face_material == 1)[0].tolist()) == synthetic.INNER_FACES[name]
        assert [fragment.visible_at(f) for f in FRAMES] == [synthetic.alive(name, f) for f in FRAMES]
        live = [f for f in FRAMES if synthetic.alive(name, f)]
        samples = [f for f in live if synthetic.sampled(name, f)]  # (none while it rests)
        np.testing.assert_array_equal(fragment.sample_frames, samples)
        for k, frame in enumerate(samples):
            position, quaternion = synthetic.pose(name, frame)
            np.testing.assert_allclose(fragment.positions[k], position, atol=1e-9)
            assert abs(abs(np.dot(fragment.orientations[k], quaternion)) - 1.0) < 1e-12
        # Consecutive samples in one hemisphere (linear key interpolation takes the short way).
        assert np.all(np.einsum("ij,ij->i", fragment.orientations[1:], fragment.orientations[:-1]) > 0)
        assert fragment.parent == (None if parent is None else f"{schema.FRAGMENTS_SCOPE}/{parent}")
        if parent is not None:
            np.testing.assert_allclose(fragment.impact_point, synthetic.IMPACT["point"], atol=1e-9)
            np.testing.assert_allclose(fragment.impact_force, synthetic.IMPACT["force"], atol=1e-9)


def test_quaternions_from_matrices_round_trip():
    reader = addon_module("reader")
    rng = np.random.default_rng(7)
    q = rng.normal(size=(500, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    q[:4] = [[0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1], [1, 0, 0, 0]]  # each branch, incl. 180 degrees
    matrices = np.array([synthetic.world_matrix((0, 0, 0), qi)[:3, :3] for qi in q])
    back = reader.quaternions_from_matrices(matrices)
    np.testing.assert_allclose(np.abs(np.einsum("ij,ij->i", back, q)), 1.0, atol=1e-12)


def test_writer_rejects_bad_input(tmp_path):
    with pytest.raises(ValueError, match="up_axis"):
        CacheWriter(tmp_path / "a.usdc", fps=24, up_axis="X")
    with pytest.raises(ValueError, match=".usd"):
        CacheWriter(tmp_path / "a.abc", fps=24)
    w = CacheWriter(tmp_path / "a.usdc", fps=24)
    vertices, faces = synthetic.box_mesh((1, 1, 1))
    with pytest.raises(ValueError, match="face_is_inner"):
        w.add_fragment("x", vertices, faces, [False] * 3, 0)
    fid = w.add_fragment("x", vertices, faces, [False] * 12, 0)
    with pytest.raises(ValueError, match="unit quaternions"):
        w.write_frame(0, [fid], [[0, 0, 0]], [[2, 0, 0, 0]])
    w.close()


def test_repeated_poses_are_held_not_sampled(tmp_path):
    """A body that rests (the same pose frame after frame, as a sleeping body) gets no
    samples while it rests: the held pose is written at the last frame that repeats it
    once the body moves again. Read back at every frame, by USD and by the add-on's keys
    (linear between samples, held after the last), the poses are the ones written."""
    path = tmp_path / "held.usda"
    vertices, faces = synthetic.box_mesh((0.1, 0.1, 0.1))
    frames = range(0, 16)
    # Moves on frames 0-3, rests 3-8, moves 9-11, rests from 11 to the end.
    x = np.array([0.0, 0.1, 0.2, 0.3, 0.3, 0.3, 0.3, 0.3, 0.3, 0.5, 0.7, 0.9] + [0.9] * 4)
    angle = np.where(np.arange(16) < 9, 0.0, 0.2 * (np.arange(16) - 8).clip(max=3))
    quats = np.stack([np.cos(angle / 2), np.zeros(16), np.zeros(16), np.sin(angle / 2)], axis=1)
    with CacheWriter(path, fps=24, checkpoint_every=1000) as writer:
        fid = writer.add_fragment("box", vertices, faces, np.zeros(len(faces), bool), 0)
        for f in frames:
            writer.write_frame(f, [fid], [[x[f], 0.0, 1.0]], [quats[f]])
    stage = Usd.Stage.Open(str(path))
    prim = fragment_prim(stage, "box")
    translate = prim.GetAttribute("xformOp:translate")
    assert translate.GetTimeSamples() == [0, 1, 2, 3, 8, 9, 10, 11]
    for f in frames:
        np.testing.assert_allclose(translate.Get(f), [x[f], 0.0, 1.0], atol=0)
        q = prim.GetAttribute("xformOp:orient").Get(f)
        np.testing.assert_allclose([q.GetReal(), *q.GetImaginary()], quats[f], atol=1e-15)
    fragment = addon_module("reader").read_cache(path).fragments[0]
    keyed = np.interp(np.asarray(frames, dtype=float), fragment.sample_frames, fragment.positions[:, 0])
    np.testing.assert_allclose(keyed, x, atol=1e-12)
    assert check_cache(path) == []


def test_checkpoints_wait_for_checkpoint_seconds(tmp_path, monkeypatch):
    """A checkpoint is due every checkpoint_every frames, but not sooner than
    checkpoint_seconds of wall time after the last write; close() writes every frame."""
    import taichi_frac.io.cache as cache_module

    now = [100.0]
    monkeypatch.setattr(cache_module._time, "monotonic", lambda: now[0])
    path = tmp_path / "throttled.usda"
    vertices, faces = synthetic.box_mesh((0.1, 0.1, 0.1))
    writer = CacheWriter(path, fps=24, checkpoint_every=2, checkpoint_seconds=5.0)
    fid = writer.add_fragment("box", vertices, faces, np.zeros(len(faces), bool), 0)
    written = []
    for frame in range(10):
        now[0] += 1.0  # one second a frame
        writer.write_frame(frame, [fid], [[0.0, 0.0, float(frame)]], [[1, 0, 0, 0]])
        if path.exists():  # (each checkpoint read from its own copy: USD caches layers by path)
            copy = path.rename(tmp_path / f"checkpoint{frame}.usda")
            stage = Usd.Stage.Open(str(copy))
            written.append((frame, stage.GetRootLayer().customLayerData[schema.LAYER_DATA_KEY][schema.KEY_LAST_FRAME]))
    # Due every 2 frames, allowed 5 s after the last write (the writer was made at t = 100).
    assert written == [(4, 4), (9, 9)]
    writer.close()
    stage = Usd.Stage.Open(str(path))
    assert stage.GetRootLayer().customLayerData[schema.LAYER_DATA_KEY][schema.KEY_COMPLETE] is True
    assert stage.GetEndTimeCode() == 9


def test_fragment_specs_match_the_schema_api(tmp_path):
    """The writer authors a fragment's specs on the layer directly; the same values
    authored through UsdGeom.Mesh, PrimvarsAPI and MaterialBindingAPI (what it used to do)
    give the same layer text: types, variability, interpolation, list ops, relationships."""
    from pxr import Gf, Sdf, Vt

    vertices, faces = synthetic.box_mesh((0.1, 0.2, 0.3))
    inner = np.zeros(len(faces), bool)
    inner[[0, 5, 7]] = True
    writer = CacheWriter(tmp_path / "direct.usda", fps=24)
    first = writer.add_fragment("first", vertices, faces, inner, 0, look=LOOKS["glass"])
    writer.add_fragment("second", vertices, faces, inner, 4, parent=first, peak_principal_stress=3e6,
                        impact=dict(point=[0.1, 0.2, 0.3], force=[1.0, -2.0, 3.0]),
                        face_peak_stress=np.arange(len(faces), dtype=float))
    direct = writer.stage

    reference = Usd.Stage.CreateInMemory("reference.usda")
    for path in (schema.ROOT_PRIM, schema.MATERIALS_SCOPE, schema.FRAGMENTS_SCOPE):
        reference.DefinePrim(path, direct.GetPrimAtPath(path).GetTypeName())
    reference.DefinePrim(f"{schema.MATERIALS_SCOPE}/first", "Scope")
    materials = {}
    for name, surface in ((schema.OUTER_SUBSET, LOOKS["glass"].outer), (schema.INNER_SUBSET, LOOKS["glass"].inner)):
        materials[name] = UsdShade.Material.Define(reference, f"{schema.MATERIALS_SCOPE}/first/{name}")
        shader = UsdShade.Shader.Define(reference, materials[name].GetPath().AppendChild("PreviewSurface"))
        shader.CreateIdAttr("UsdPreviewSurface")
        shader.CreateInput("diffuseColor", Sdf.ValueTypeNames.Color3f).Set(Gf.Vec3f(*surface.diffuse_color))
        for key in ("roughness", "metallic", "opacity", "ior"):
            shader.CreateInput(key, Sdf.ValueTypeNames.Float).Set(getattr(surface, key))
        shader.CreateInput("opacityThreshold", Sdf.ValueTypeNames.Float).Set(0.0)
        materials[name].CreateSurfaceOutput().ConnectToSource(shader.ConnectableAPI(), "surface")
    for name in ("first", "second"):
        source = direct.GetPrimAtPath(f"{schema.FRAGMENTS_SCOPE}/{name}")
        value = lambda attr: source.GetAttribute(attr).Get()  # noqa: E731
        mesh = UsdGeom.Mesh.Define(reference, source.GetPath())
        mesh.CreatePointsAttr(value("points"))
        mesh.CreateFaceVertexCountsAttr(value("faceVertexCounts"))
        mesh.CreateFaceVertexIndicesAttr(value("faceVertexIndices"))
        mesh.CreateExtentAttr(value("extent"))
        mesh.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)
        mesh.CreateNormalsAttr(value("normals"))
        mesh.SetNormalsInterpolation(UsdGeom.Tokens.faceVarying)
        primvars = UsdGeom.PrimvarsAPI(mesh)
        primvars.CreatePrimvar(schema.PRIMVAR_UV, Sdf.ValueTypeNames.TexCoord2fArray,
                               UsdGeom.Tokens.faceVarying).Set(value(f"primvars:{schema.PRIMVAR_UV}"))
        primvars.CreatePrimvar(schema.PRIMVAR_FACE_STRESS, Sdf.ValueTypeNames.FloatArray,
                               UsdGeom.Tokens.uniform).Set(value(f"primvars:{schema.PRIMVAR_FACE_STRESS}"))
        binding = UsdShade.MaterialBindingAPI.Apply(mesh.GetPrim())
        for subset_name in (schema.OUTER_SUBSET, schema.INNER_SUBSET):
            indices = direct.GetPrimAtPath(f"{source.GetPath()}/{subset_name}").GetAttribute("indices").Get()
            subset = binding.CreateMaterialBindSubset(subset_name, Vt.IntArray(indices), UsdGeom.Tokens.face)
            UsdShade.MaterialBindingAPI.Apply(subset.GetPrim()).Bind(materials[subset_name])
        binding.SetMaterialBindSubsetsFamilyType(UsdGeom.Tokens.partition)
        prim = mesh.GetPrim()
        for attr in (schema.ATTR_BIRTH_FRAME, schema.ATTR_DEATH_FRAME, schema.ATTR_PEAK_STRESS,
                     schema.ATTR_IMPACT_POINT, schema.ATTR_IMPACT_FORCE):
            if source.GetAttribute(attr):
                prim.CreateAttribute(attr, source.GetAttribute(attr).GetTypeName(), custom=True).Set(value(attr))
        if source.GetRelationship(schema.ATTR_PARENT):
            prim.CreateRelationship(schema.ATTR_PARENT, custom=True).SetTargets(
                source.GetRelationship(schema.ATTR_PARENT).GetTargets())
        mesh.AddTranslateOp(UsdGeom.XformOp.PrecisionDouble)
        mesh.AddOrientOp(UsdGeom.XformOp.PrecisionDouble)
        visibility = mesh.CreateVisibilityAttr()
        for t in source.GetAttribute("visibility").GetTimeSamples():
            visibility.Set(source.GetAttribute("visibility").Get(t), Usd.TimeCode(t))

    def fragments_text(stage):
        text = stage.GetRootLayer().ExportToString()
        return text[text.index('def Scope "Fragments"'):]

    def materials_text(stage):
        text = stage.GetRootLayer().ExportToString()
        return text[text.index('def Scope "Materials"'):text.index('def Scope "Fragments"')]

    assert fragments_text(direct) == fragments_text(reference)
    assert materials_text(direct) == materials_text(reference)
    assert isinstance(direct.GetPrimAtPath(f"{schema.FRAGMENTS_SCOPE}/second").GetAttribute(
        schema.ATTR_IMPACT_POINT).Get(), Gf.Vec3d)
    writer.close()


def test_each_body_gets_its_material_look(tmp_path):
    """A glass body and a porcelain one: each gets two UsdPreviewSurface materials with its
    look's inputs (glass transmissive: opacity < 1 with opacityThreshold 0), its pieces bind
    the same two, and the cache stays compliant."""
    vertices, faces = synthetic.box_mesh((0.1, 0.2, 0.3))
    inner = np.zeros(len(faces), bool)
    inner[:4] = True
    path = tmp_path / "looks.usda"
    writer = CacheWriter(path, fps=24)
    pane = writer.add_fragment("pane", vertices, faces, inner, 0, look=LOOKS["glass"])
    writer.add_fragment("pane_0", vertices, faces, inner, 3, parent=pane)
    writer.add_fragment("cup", vertices, faces, inner, 0, look=LOOKS["porcelain"])
    writer.add_fragment("plain", vertices, faces, inner, 0)
    writer.close()
    assert check_cache(path) == []
    stage = Usd.Stage.Open(str(path))

    def bound_inputs(fragment, subset_name):
        subset = stage.GetPrimAtPath(f"{schema.FRAGMENTS_SCOPE}/{fragment}/{subset_name}")
        material = UsdShade.MaterialBindingAPI(subset).ComputeBoundMaterial()[0]
        shader = material.ComputeSurfaceSource()[0]
        return material.GetPath(), {i.GetBaseName(): i.Get() for i in shader.GetInputs()}

    for fragment, body, look in (("pane", "pane", "glass"), ("pane_0", "pane", "glass"),
                                 ("cup", "cup", "porcelain"), ("plain", "plain", "plaster")):
        for subset_name in (schema.OUTER_SUBSET, schema.INNER_SUBSET):
            path_bound, inputs = bound_inputs(fragment, subset_name)
            assert path_bound == f"{schema.MATERIALS_SCOPE}/{body}/{subset_name}"
            surface = getattr(LOOKS[look], subset_name)
            np.testing.assert_allclose(inputs["diffuseColor"], surface.diffuse_color, atol=1e-6)
            for key in ("roughness", "metallic", "opacity", "ior"):
                assert inputs[key] == pytest.approx(getattr(surface, key), abs=1e-6), (fragment, key)
            assert inputs["opacityThreshold"] == 0.0
    assert bound_inputs("pane", "outer")[1]["opacity"] < 0.5  # glass lets light through
    assert bound_inputs("pane", "inner")[1]["roughness"] > bound_inputs("pane", "outer")[1]["roughness"]  # frosted
    assert bound_inputs("cup", "outer")[1]["opacity"] == 1.0


def test_material_presets_carry_their_look():
    from taichi_frac.options import MATERIAL_PRESETS, Material, OptionError
    assert {name: m.look for name, m in MATERIAL_PRESETS.items()} == {
        "soda_lime_glass": "glass", "porcelain": "porcelain", "concrete": "concrete"}
    with pytest.raises(OptionError, match="material.look = 'marble'"):
        Material(look="marble")
