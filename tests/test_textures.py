"""The film look (issue 15): generated bark and leaf-card textures, the
same bytes every time, embedded in the glb (alpha-mask, double-sided
cards), referenced from the OBJ's .mtl (read back by trimesh) and from
USD preview surfaces; `textures=False` (--no-textures) writes plain
materials."""

import io
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
from treebake.exchange import materials, textures
from treebake.exchange.foliage import ATLAS, STYLES
from treebake.export import ExportOptions, export_bake


def test_textures_are_deterministic_and_well_formed():
    bark = textures.bark_texture()
    textures.bark_texture.cache_clear()
    textures.leaf_texture.cache_clear()
    assert textures.bark_texture().png == bark.png
    img = np.asarray(Image.open(io.BytesIO(bark.png)).convert("RGB")).astype(int)
    assert img.shape == (512, 256, 3) and bark.repeat and not bark.cutout
    # tileable: the seam (last column to first, last row to first) is no rougher
    # than any neighbouring pair of columns or rows
    cols = np.abs(np.diff(img, axis=1)).mean()
    rows = np.abs(np.diff(img, axis=0)).mean()
    assert np.abs(img[:, -1] - img[:, 0]).mean() < 2 * cols
    assert np.abs(img[-1] - img[0]).mean() < 2 * rows
    n, size = ATLAS, textures.CARD_SIZE
    for kind in (1, 2, 3):
        card = textures.leaf_texture(kind)
        rgba = np.asarray(Image.open(io.BytesIO(card.png)))
        assert rgba.shape == (n * size, n * size, 4) and card.cutout and not card.repeat
        assert set(np.unique(rgba[..., 3])) == {0, 255}  # a clean mask
        means = []
        for j in range(n):  # an atlas of cards, rows from the bottom (v up)
            for i in range(n):
                cell = rgba[(n - 1 - j) * size:(n - j) * size, i * size:(i + 1) * size]
                alpha = cell[..., 3]
                # leaves and gaps, as opaque as the foliage's card count assumes
                assert (alpha > 0).mean() == pytest.approx(STYLES[kind].fill, abs=0.02)
                assert alpha[-1].any()  # the stem reaches the card's bottom edge (v = 0)
                # nothing touches the cell's other edges (no bleeding between cells)
                assert not alpha[0].any() and not alpha[:, 0].any() and not alpha[:, -1].any()
                means.append(cell[alpha > 0][:, :3].mean(0))
        # the variants differ in colour: hue and value, a few percent at least
        means = np.array(means)
        assert np.ptp(means.sum(1)) > 0.1 * means.sum(1).mean()
        hue = means / means.sum(1, keepdims=True)
        assert np.ptp(hue[:, 0]) > 0.02 and np.ptp(hue[:, 2]) > 0.02
    assert materials.texture_for("leaf2").name == "leaf2.png"  # conifers: needle cards
    assert materials.texture_for("object") is None


@pytest.fixture(scope="module")
def demo(tmp_path_factory):
    out = tmp_path_factory.mktemp("look")
    formats = ("glb", "obj", "usda")
    bake = preset_bake("demo")
    tex = export_bake(bake, out, "tex", ExportOptions(formats=formats, obj_stride=100))
    plain = export_bake(bake, out, "plain", ExportOptions(formats=formats, obj_stride=100,
                                                          textures=False))
    return bake, tex, plain


def test_glb_embeds_the_textures(demo):
    _, tex, plain = demo
    g = Gltf(tex.folder / "tex.glb")
    mats = {m.name: m for m in g.g.materials}
    # issue 40: each species its own bark (the demo's oak, spruce and sapling)
    assert {"bark_oak", "bark_spruce", "bark_sapling", "leaf", "leaf2"} <= set(mats)
    for name, m in mats.items():
        info = m.pbrMetallicRoughness.baseColorTexture
        assert info is not None
        image = g.g.images[g.g.textures[info.index].source]
        assert image.mimeType == "image/png"
        view = g.g.bufferViews[image.bufferView]
        png = g.blob[view.byteOffset:view.byteOffset + view.byteLength]
        assert png == materials.texture_for(name).png
        if name.startswith("leaf"):
            assert m.alphaMode == "MASK" and m.alphaCutoff == 0.5 and m.doubleSided
    assert tex.manifest["settings"]["textures"] is True
    g0 = Gltf(plain.folder / "plain.glb")
    assert not g0.g.images and all(m.pbrMetallicRoughness.baseColorTexture is None
                                   for m in g0.g.materials)
    assert not (plain.folder / "textures").exists()


def test_obj_mtl_references_the_textures_trimesh_loads_them(demo):
    trimesh = need("trimesh")
    _, tex, plain = demo
    mtl = (tex.folder / "obj" / "tex.mtl").read_text()
    assert "map_Kd textures/bark_oak.png" in mtl and "map_d textures/leaf.png" in mtl
    for line in mtl.splitlines():
        if line.startswith("map_"):
            assert (tex.folder / "obj" / line.split()[1]).is_file()
    scene = trimesh.load(tex.folder / "obj" / "tex.0001.obj", force="scene")
    images = [g.visual.material.image for g in scene.geometry.values()
              if getattr(g.visual, "material", None) is not None]
    assert any(im is not None for im in images)
    assert "map_Kd" not in (plain.folder / "obj" / "plain.mtl").read_text()


def test_usd_preview_surfaces_read_the_texture_files(demo):
    need("pxr")
    from pxr import Sdf, Usd, UsdShade

    _, tex, plain = demo
    stage = Usd.Stage.Open(str(tex.folder / "tex.usda"))
    for name in ("bark_oak", "leaf", "leaf2"):
        surface = UsdShade.Shader(stage.GetPrimAtPath(f"/tex/Looks/{name}/PreviewSurface"))
        source = surface.GetInput("diffuseColor").GetConnectedSources()[0][0]
        reader = UsdShade.Shader(source.source.GetPrim())
        assert reader.GetIdAttr().Get() == "UsdUVTexture"
        asset = reader.GetInput("file").Get()
        assert isinstance(asset, Sdf.AssetPath) and Path(asset.resolvedPath).is_file()
        if name.startswith("leaf"):
            assert surface.GetInput("opacityThreshold").Get() == 0.5
            assert surface.GetInput("opacity").HasConnectedSource()
    flat = Usd.Stage.Open(str(plain.folder / "plain.usda"))
    surface = UsdShade.Shader(flat.GetPrimAtPath("/plain/Looks/bark/PreviewSurface"))
    assert not surface.GetInput("diffuseColor").HasConnectedSource()


def test_no_textures_flag(tmp_path, capsys):
    bake = tmp_path / "b.npz"
    from treebake.bake_file import save_bake

    save_bake(preset_bake("calm"), bake)
    assert main(["export", str(bake), "--format", "obj", "--no-textures", "--out",
                 str(tmp_path), "--name", "n", "-q"]) == 0
    assert not (tmp_path / "n" / "obj" / "textures").exists()
    assert main(["export", str(bake), "--format", "obj", "--out", str(tmp_path), "--name",
                 "t", "-q"]) == 0
    # issue 40: the calm preset's oak gets the oak's bark and its normal map
    assert (tmp_path / "t" / "obj" / "textures" / "bark_oak.png").is_file()
    assert (tmp_path / "t" / "obj" / "textures" / "bark_oak_normal.png").is_file()
