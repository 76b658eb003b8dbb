"""Issue 40 item 3: bark per species with a tangent-space normal map
(glb normalTexture + TANGENT, USD preview surface `normal`, the .mtl's
norm / map_Bump), and the export's `detail` levels (hero, default, far):
fewer triangles far, more hero, today's mesh at default, and the bake the
same bytes at every level."""

import io
from dataclasses import replace
import sys
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

sys.path.insert(0, str(Path(__file__).resolve().parent / "tools"))

from bakes import preset_bake
from conftest import need
from gltfread import Gltf
from treebake.cli import main
from treebake.model import Twigs
from treebake.exchange import bark, materials, textures
from treebake.exchange.mesh import MeshOptions, tree_mesh
from treebake.export import ExportOptions, export_bake
from treebake.tree_meshes import TreeMeshes

SPECIES = sorted(bark.STYLES)


def _decode(png: bytes) -> np.ndarray:
    """A normal map's PNG -> (h, w, 3) tangent-space vectors, -1..1."""
    return np.asarray(Image.open(io.BytesIO(png)).convert("RGB")).astype(np.float64) / 127.5 - 1


def test_bark_textures_are_deterministic_and_differ_between_species():
    first = {s: bark.species_bark(s) for s in SPECIES}
    bark.species_bark.cache_clear()
    for s in SPECIES:
        again = bark.species_bark(s)
        assert again.png == first[s].png and again.normal.png == first[s].normal.png
        assert again.repeat and not again.cutout and again.normal.linear
        assert again.name == f"bark_{s}.png" and again.normal.name == f"bark_{s}_normal.png"
    # the forest conifer shares the spruce's style but not its noise
    assert len({t.png for t in first.values()}) == len(SPECIES)
    assert len({t.normal.png for t in first.values()}) == len(SPECIES)
    # birch bark is white, the others are not; bamboo is green
    mean = {s: np.asarray(Image.open(io.BytesIO(t.png))).reshape(-1, 3).mean(0)
            for s, t in first.items()}
    assert mean["birch"].min() > 170 and all(mean[s].mean() < 150 for s in SPECIES
                                             if s != "birch")
    assert mean["bamboo"][1] > mean["bamboo"][0] > mean["bamboo"][2]


@pytest.mark.parametrize("species", SPECIES)
def test_normal_maps_are_unit_tangent_space_normals(species):
    tex = bark.species_bark(species)
    n = _decode(tex.normal.png)
    w, h = textures.BARK_SIZE
    assert n.shape == (h, w, 3)
    length = np.linalg.norm(n, axis=-1)
    assert np.abs(length - 1).max() < 0.01  # unit, up to 8-bit rounding
    assert n[..., 2].min() > 0  # tangent space: every normal leans out of the surface
    mean = n.reshape(-1, 3).mean(0)  # a relief that tiles has no mean slope
    assert np.abs(mean[:2]).max() < 0.01 and 0.85 < mean[2] <= 1.0
    assert mean[2] < 0.999  # there is relief to see
    # colour and normals tile: the seam (last column to first, last row to
    # first) is no rougher than the roughest pair of neighbouring columns / rows
    for img in (np.asarray(Image.open(io.BytesIO(tex.png))).astype(int), n):
        cols = np.abs(np.diff(img, axis=1)).mean(axis=(0, 2))
        rows = np.abs(np.diff(img, axis=0)).mean(axis=(1, 2))
        assert np.abs(img[:, -1] - img[:, 0]).mean() <= cols.max()
        assert np.abs(img[-1] - img[0]).mean() <= rows.max()


def test_normal_map_of_a_known_relief():
    """A ramp up along +u (columns) and another along +v (rows, v up) give
    the analytic normals (-s, 0, 1) / sqrt(1 + s^2) and (0, -s, 1) / ...:
    x right = +u, y up = +v (glTF's and USD's tangent space)."""
    h, w, s = 64, 32, 0.5
    # a triangle wave in u: rises 16 texels over 16 columns, falls back over 16
    tri = np.r_[np.arange(16), 16 - np.arange(16)]
    z_u = np.tile(tri * 65535 // 16, (h, 1))
    n = normal_map_float(z_u, 16 * s, 1.0)
    want = np.array([-s, 0, 1]) / np.sqrt(1 + s * s)
    np.testing.assert_allclose(n[:, 4:12].reshape(-1, 3), np.tile(want, (h * 8, 1)), atol=0.01)
    tri_v = np.r_[np.arange(32), 32 - np.arange(32)]
    z_v = np.tile((tri_v * 65535 // 32)[:, None], (1, w))  # rows = v up, before the flip
    n = normal_map_float(z_v, 32 * s, 1.0)
    want = np.array([0, -s, 1]) / np.sqrt(1 + s * s)
    np.testing.assert_allclose(n[4:28].reshape(-1, 3), np.tile(want, (24 * w, 1)), atol=0.01)
    # at twice the texels a texel is half as long: the same relief, the same normals
    n2 = normal_map_float(np.repeat(z_v, 2, axis=0), 32 * s, 2.0)
    np.testing.assert_allclose(n2[8:56:2], n[4:28], atol=0.01)


def normal_map_float(height, depth, scale):
    out = textures.normal_map(np.asarray(height, np.int64), depth, scale)
    return out.astype(np.float64) / 127.5 - 1


def test_species_from_grammar_file():
    assert bark.bark_material("../grammars/oak.lsys") == "bark_oak"
    assert bark.bark_material("grammars/forest/birch.lsys") == "bark_birch"
    assert bark.bark_material("forest\\conifer.lsys") == "bark_conifer"
    assert bark.bark_material("my_tree.lsys") == "bark" and bark.bark_material(None) == "bark"


@pytest.fixture(scope="module")
def calm(tmp_path_factory):
    """The calm preset (an oak and a spruce) in glb, usda and obj."""
    out = tmp_path_factory.mktemp("bark")
    bake = preset_bake("calm")
    rep = export_bake(bake, out, "c", ExportOptions(formats=("glb", "usda", "obj")))
    return bake, rep


def test_glb_bark_materials_carry_normal_maps_and_tangents(calm):
    from validator import validate

    _, rep = calm
    path = rep.folder / "c.glb"
    g = Gltf(path)
    barks = [m for m in g.g.materials if m.name.startswith("bark")]
    assert {m.name for m in barks} == {"bark_oak", "bark_spruce"}
    for m in barks:
        info = m.normalTexture
        assert info is not None
        image = g.g.images[g.g.textures[info.index].source]
        view = g.g.bufferViews[image.bufferView]
        png = g.blob[view.byteOffset:view.byteOffset + view.byteLength]
        assert png == materials.texture_for(m.name).normal.png
    for mesh in g.g.meshes:
        for prim in mesh.primitives:
            mat = g.g.materials[prim.material]
            has = prim.attributes.TANGENT is not None
            assert has == (mat.normalTexture is not None), (mesh.name, mat.name)
    (report,) = validate([path])
    assert report["errors"] == 0 and report["warnings"] == 0, report["messages"][:5]
    assert report["infos"] == 0, report  # no unused tangents


def test_bark_tangents_run_around_the_limb():
    """TANGENT xyz is d(position)/du (around the ring), unit, across the
    normal, and N x T points along the limb (+v): checked against finite
    differences of the mesh's own positions and UVs."""
    bake = preset_bake("calm")
    # the bark's tubes (a twig's tube has fewer sides: tests/test_twigs.py)
    mesh = tree_mesh(replace(bake.trees[0], twigs=Twigs.none()))
    t, n = mesh.tangents[:, :3], mesh.normals
    assert np.allclose(mesh.tangents[:, 3], 1.0)
    np.testing.assert_allclose(np.linalg.norm(t, axis=1), 1.0, atol=1e-9)
    assert np.abs((t * n).sum(1)).max() < 1e-9
    faces = mesh.parts[0].faces
    a, b, c = faces[:, 0], faces[:, 1], faces[:, 2]
    # tube triangles (a, a + 1, b + 1): a -> a + 1 steps u only, b + 1 shares
    # a + 1's u on the next station (a cap's centre has no such neighbour)
    du_ok = np.abs(mesh.uvs[b, 1] - mesh.uvs[a, 1]) < 1e-12
    du_ok &= (mesh.uvs[b, 0] > mesh.uvs[a, 0]) & (mesh.uvs[c, 0] == mesh.uvs[b, 0])
    du_ok &= mesh.uvs[c, 1] != mesh.uvs[a, 1]
    step = mesh.positions[b[du_ok]] - mesh.positions[a[du_ok]]
    cos = (step * t[a[du_ok]]).sum(1) / np.linalg.norm(step, axis=1)
    assert len(cos) > 100 and cos.min() > 0.9  # a ring step of 45 degrees: cos 22.5 = 0.92
    along = c[du_ok]  # b + 1's ring is the next station along the limb
    dv = mesh.positions[along] - mesh.positions[a[du_ok]]
    nt = np.cross(n[a[du_ok]], t[a[du_ok]])
    rising = mesh.uvs[along, 1] > mesh.uvs[a[du_ok], 1]
    assert ((dv * nt).sum(1)[rising] > 0).all()


def test_usd_normal_map_network(calm):
    need("pxr")
    from pxr import Gf, Sdf, Usd, UsdShade
    from treebake.exchange.usd import validate

    _, rep = calm
    stage = Usd.Stage.Open(str(rep.folder / "c.usda"))
    for name in ("bark_oak", "bark_spruce"):
        surface = UsdShade.Shader(stage.GetPrimAtPath(f"/c/Looks/{name}/PreviewSurface"))
        normal = surface.GetInput("normal")
        assert normal.GetTypeName() == Sdf.ValueTypeNames.Normal3f
        (src,), _ = normal.GetConnectedSources()
        assert src.sourceName == "rgb"
        tex = UsdShade.Shader(src.source.GetPrim())
        assert tex.GetIdAttr().Get() == "UsdUVTexture"
        assert tex.GetInput("sourceColorSpace").Get() == "raw"
        assert tex.GetInput("scale").Get() == Gf.Vec4f(2, 2, 2, 1)
        assert tex.GetInput("bias").Get() == Gf.Vec4f(-1, -1, -1, 0)
        asset = tex.GetInput("file").Get()
        assert Path(asset.resolvedPath).name == f"{name}_normal.png"
        assert Path(asset.resolvedPath).read_bytes() == materials.texture_for(name).normal.png
        # read at the same st as the colour
        (st,), _ = tex.GetInput("st").GetConnectedSources()
        assert UsdShade.Shader(st.source.GetPrim()).GetIdAttr().Get() == "UsdPrimvarReader_float2"
    assert validate(rep.folder / "c.usda") == []


def test_mtl_names_the_normal_map(calm):
    _, rep = calm
    mtl = (rep.folder / "obj" / "c.mtl").read_text()
    block = mtl.split("newmtl bark_oak")[1].split("newmtl")[0]
    assert "map_Kd textures/bark_oak.png" in block
    assert "norm textures/bark_oak_normal.png" in block
    assert "map_Bump textures/bark_oak_normal.png" in block
    assert (rep.folder / "obj" / "textures" / "bark_oak_normal.png").is_file()
    leaf = mtl.split("newmtl leaf\n")[1].split("newmtl")[0]
    assert "norm " not in leaf and "map_Bump" not in leaf


def test_detail_levels_trade_triangles_default_is_todays_mesh():
    bake = preset_bake("forest")
    counts = {}
    for level in ("hero", "default", "far"):
        meshes = TreeMeshes(bake, MeshOptions(), level, species=True)
        counts[level] = [meshes[i].n_triangles for i in range(len(bake.trees))]
        if level == "default":  # today's geometry, only the bark material is new
            for i in (0, len(bake.trees) - 1):
                new, old = meshes[i], tree_mesh(bake.trees[i])
                for key in ("positions", "normals", "uvs", "joints", "weights"):
                    assert np.array_equal(getattr(new, key), getattr(old, key)), key
                for p, q in zip(new.parts, old.parts):
                    assert np.array_equal(p.faces, q.faces) and p.material == q.material
                assert new.parts[0].shader.startswith("bark_")
    hero, default, far = (np.array(counts[k]) for k in ("hero", "default", "far"))
    assert (far < default).all() and (hero > default).all()
    assert far.sum() < 0.6 * default.sum()  # substantially fewer


def test_bake_is_the_same_at_every_detail_level(tmp_path):
    """Detail is an export option (no scene key: a scene's text, so its
    hash, is in the bake): the bake's bytes do not move, and every level's
    glb carries the same joints and animation, only other meshes."""
    assert main(["bake", "sapling", "--duration", "0.2", "--out", str(tmp_path), "-q"]) == 0
    (npz,) = tmp_path.glob("*/*.npz")
    before = npz.read_bytes()
    motion, tris = {}, {}
    for level in ("far", "default", "hero"):
        assert main(["export", str(npz), "--format", "glb", "--no-reduce", "--detail", level,
                     "--out", str(tmp_path), "--name", level, "-q"]) == 0
        g = Gltf(tmp_path / level / f"{level}.glb")
        assert g.g.materials[0].normalTexture is not None
        samplers = g.g.animations[0].samplers
        motion[level] = (len(g.g.nodes), [g.accessor(s.output).tobytes() for s in samplers])
        tris[level] = sum(g.accessor(p.indices).size // 3 for m in g.g.meshes
                          for p in m.primitives)
        assert npz.read_bytes() == before
    assert motion["far"] == motion["default"] == motion["hero"]
    assert tris["far"] < tris["default"] < tris["hero"]


def test_detail_bad_level_is_a_clear_error(tmp_path, capsys):
    from treebake.bake_file import save_bake

    path = tmp_path / "b.npz"
    save_bake(preset_bake("calm"), path)
    assert main(["export", str(path), "--detail", "medium", "--out", str(tmp_path)]) == 2
    assert "hero, default, far" in capsys.readouterr().err
    assert main(["export", str(path), "--detail", "far,nosuchtree=hero",
                 "--out", str(tmp_path)]) == 2
    assert "nosuchtree" in capsys.readouterr().err
    # per tree: the oak hero, the rest far
    names = [t.name for t in preset_bake("calm").trees]
    assert main(["export", str(path), "--detail", f"far,{names[0]}=hero", "--out",
                 str(tmp_path), "--name", "mixed", "-q"]) == 0
    import json

    man = json.loads((tmp_path / "mixed" / "manifest.json").read_text())
    assert man["settings"]["detail"] == "far"
    assert man["settings"]["detail_trees"] == {names[0]: "hero"}
