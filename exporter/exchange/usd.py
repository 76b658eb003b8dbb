"""USD writer (optional dependency `usd-core`): UsdSkel skeletons with
per-frame joint animation, skinned bark and leaf meshes, UsdPreviewSurface
materials, projectiles as Xforms with time-sampled translate/orient.

Stage metadata: upAxis "Y" (coordinates converted like glTF:
(x, y, z) -> (x, z, -y)), metersPerUnit 1, timeCodesPerSecond =
framesPerSecond = the bake's fps, startTimeCode = frame_start, endTimeCode =
frame_start + frames - 1 (time code = frame_start + bake time x fps: frame
numbers like the OBJ sequence's; extra sub-frame samples get fractional
codes, on a skeleton only inside the frame intervals where one of its
joints turns more than sampling.FAST_TURN_DEG), defaultPrim = the job's root
Xform. Joints carry the glTF joint names (names.py, `oak_trunk_2_1_s3`)
in a path hierarchy that follows the segments; the
original segment paths are in the Skeleton's `treebake:segmentPaths`
attribute. Static trees are plain meshes.
"""

from __future__ import annotations

import errno
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..bake import Bake
from ..bake_file import tree_info
from ..errors import InputError, TreebakeError
from ..fileio import atomic_path
from ..names import joint_names
from ..rotations import continuous, qnormalize
from .anim import local_transforms
from .axes import points_y_up, quats_y_up
from .mesh import OBJECT_COLOUR, TreeMesh, object_mesh
from .textures import TextureMap


MISSING = "USD export needs the optional dependency usd-core: pip install 'treebake[usd]'"


def require() -> None:
    """Raise InputError naming `treebake[usd]` unless pxr imports (called
    before any simulation when usd or usda is asked for)."""
    try:
        import pxr  # noqa: F401
    except ImportError:
        raise InputError(MISSING) from None


def _pxr():
    try:
        from pxr import Gf, Sdf, Tf, Vt
    except ImportError:  # pragma: no cover - depends on the install
        raise TreebakeError(MISSING) from None
    return Gf, Sdf, Tf, Vt


@dataclass
class UsdResult:
    files: list[Path] = field(default_factory=list)
    joints: int = 0
    time_codes: tuple[float, float] = (1.0, 1.0)
    subframe_codes: int = 0  # fractional time codes written, summed over skeletons
    validation_errors: list[str] = field(default_factory=list)
    layers_checked: int = 0  # tree layers validated on their own ("tree" layers)


def joint_tokens(parent: np.ndarray, names: list[str]) -> list[str]:
    """UsdSkel joint paths: each joint's name under its parent's path, so the
    path follows the tree (`oak_trunk_s0/oak_trunk_s1/oak_trunk_1_s0`)."""
    out: list[str] = []
    for s, p in enumerate(parent.tolist()):  # parents come first
        out.append(names[s] if p < 0 else f"{out[p]}/{names[s]}")
    return out


class _Writer:
    """One USD layer authored directly as Sdf specs (no stage: a third of
    the CPU of the Usd schema API per tree, the same layer): prims,
    attributes and relationships exactly as the UsdGeom, UsdSkel and
    UsdShade schemas define them."""

    def __init__(self, bake: Bake, name: str, frame_start: int = 1,
                 maps: dict[str, TextureMap] | None = None,
                 kind: str = "assembly") -> None:
        Gf, Sdf, Tf, Vt = _pxr()
        self.Gf, self.Sdf, self.Tf, self.Vt = Gf, Sdf, Tf, Vt
        self.types = Sdf.ValueTypeNames
        self.bake = bake
        self.layer = Sdf.Layer.CreateAnonymous(".usd")
        info = self.layer.pseudoRoot
        info.SetInfo("upAxis", "Y")
        info.SetInfo("metersPerUnit", 1.0)
        fps = float(bake.fps)
        info.SetInfo("timeCodesPerSecond", fps)
        info.SetInfo("framesPerSecond", fps)
        self.frame_start = frame_start
        info.SetInfo("startTimeCode", float(frame_start))
        info.SetInfo("endTimeCode", float(frame_start + len(bake.times) - 1))
        self.root = f"/{self.ident(name)}"
        root = self.prim(self.root, "Xform")
        self.layer.defaultPrim = root.name
        root.kind = kind
        self.materials: set[str] = set()
        self.maps = maps or {}  # material -> its textures' paths relative to the file
        self.used: set[str] = {f"{self.root}/Looks", f"{self.root}/Projectiles"}
        self.subframe_codes = 0  # fractional time codes written, summed over skeletons

    def ident(self, name: str) -> str:
        return self.Tf.MakeValidIdentifier(str(name)) or "unnamed"

    def unique(self, parent: str, name: str) -> str:
        base = self.ident(name)
        path, k = f"{parent}/{base}", 1
        while path in self.used:
            k += 1
            path = f"{parent}/{base}_{k}"
        self.used.add(path)
        return path

    def prim(self, path: str, type_name: str = ""):
        """A `def` prim at `path` (its parent defined already, or a typeless
        `def` made for it, as UsdStage.DefinePrim does)."""
        Sdf = self.Sdf
        parent, name = path.rsplit("/", 1)
        owner = self.layer.GetPrimAtPath(parent) if parent else self.layer
        if owner is None:
            owner = self.prim(parent)
        return Sdf.PrimSpec(owner, name, Sdf.SpecifierDef, type_name)

    def attr(self, prim, name: str, type_name, value=None, uniform: bool = False,
             custom: bool = False, **info):
        """An attribute of `prim` with metadata `info` and default `value`
        (None: none), authored in the order the schema API authors them."""
        Sdf = self.Sdf
        spec = Sdf.AttributeSpec(prim, name, type_name,
                                 Sdf.VariabilityUniform if uniform else Sdf.VariabilityVarying,
                                 declaresCustom=custom)
        for key, v in info.items():
            spec.SetInfo(key, v)
        if value is not None:
            spec.default = value
        return spec

    def connect(self, attr, source, output: str) -> None:
        """Connect the shader input `attr` to the output `output` of the
        prim `source`, made with the input's type if it is not there."""
        if source.attributes.get(f"outputs:{output}") is None:
            self.attr(source, f"outputs:{output}", attr.typeName)
        attr.connectionPathList.explicitItems = [source.path.AppendProperty(f"outputs:{output}")]

    def rel(self, prim, name: str, target: str) -> None:
        """A relationship of `prim` targeting the prim path `target`."""
        spec = self.Sdf.RelationshipSpec(prim, name, custom=False)
        spec.targetPathList.explicitItems = [self.Sdf.Path(target)]

    def apply(self, prim, schema: str) -> None:
        """API `schema` added to the schemas `prim` applies."""
        ops = prim.GetInfo("apiSchemas") if prim.HasInfo("apiSchemas") else None
        items = list(ops.prependedItems) if ops is not None else []
        prim.SetInfo("apiSchemas", self.Sdf.TokenListOp.Create(prependedItems=items + [schema]))

    def material(self, name: str, colour) -> str:
        """The path of material `name` under the root's Looks, a
        UsdPreviewSurface, textured where `maps` has it, else `colour`."""
        path = f"{self.root}/Looks/{self.ident(name)}"
        if name in self.materials:
            return path
        self.materials.add(name)
        T = self.types
        mat = self.prim(path, "Material")
        sh = self.prim(f"{path}/PreviewSurface", "Shader")
        self.attr(sh, "info:id", T.Token, "UsdPreviewSurface", uniform=True)
        diffuse = self.attr(sh, "inputs:diffuseColor", T.Color3f)
        if name in self.maps:
            self.texture(path, sh, diffuse, self.maps[name])
        else:
            diffuse.default = self.Gf.Vec3f(*[float(c) for c in colour])
        self.attr(sh, "inputs:roughness", T.Float, 0.9)
        self.attr(sh, "inputs:metallic", T.Float, 0.0)
        self.connect(self.attr(mat, "outputs:surface", T.Token), sh, "surface")
        return path

    def texture(self, path: str, surface, diffuse, maps: TextureMap) -> None:
        """diffuseColor (and for cutout cards opacity, thresholded at 0.5)
        from a UsdUVTexture reading `maps.path` at the mesh's `st` primvar;
        with a normal map, `normal` from a second UsdUVTexture reading it as
        raw data, scale 2 and bias -1 (tangent space, -1..1)."""
        T, Gf = self.types, self.Gf
        reader = self.prim(f"{path}/stReader", "Shader")
        self.attr(reader, "info:id", T.Token, "UsdPrimvarReader_float2", uniform=True)
        self.attr(reader, "inputs:varname", T.String, "st")
        cutout = maps.cutout
        tex = self.uv_texture(f"{path}/Texture", maps.path, "sRGB", cutout, reader)
        self.connect(diffuse, tex, "rgb")
        if maps.normal is not None:
            nrm = self.uv_texture(f"{path}/NormalTexture", maps.normal, "raw", cutout, reader)
            self.attr(nrm, "inputs:scale", T.Float4, Gf.Vec4f(2, 2, 2, 1))
            self.attr(nrm, "inputs:bias", T.Float4, Gf.Vec4f(-1, -1, -1, 0))
            self.connect(self.attr(surface, "inputs:normal", T.Normal3f), nrm, "rgb")
        if cutout:
            self.connect(self.attr(surface, "inputs:opacity", T.Float), tex, "a")
            self.attr(surface, "inputs:opacityThreshold", T.Float, 0.5)

    def uv_texture(self, path: str, file: str, colour_space: str, clamp: bool, reader):
        """A UsdUVTexture at `path` reading `file` at the `reader`'s `st`."""
        T = self.types
        tex = self.prim(path, "Shader")
        self.attr(tex, "info:id", T.Token, "UsdUVTexture", uniform=True)
        self.attr(tex, "inputs:file", T.Asset, self.Sdf.AssetPath(file))
        self.attr(tex, "inputs:sourceColorSpace", T.Token, colour_space)
        wrap = "clamp" if clamp else "repeat"
        self.attr(tex, "inputs:wrapS", T.Token, wrap)
        self.attr(tex, "inputs:wrapT", T.Token, wrap)
        self.connect(self.attr(tex, "inputs:st", T.Float2), reader, "result")
        return tex

    def meshes(self, parent: str, mesh: TreeMesh, skel_path: str | None,
               offset: np.ndarray | None = None) -> None:
        """One Mesh prim per material part, vertices compacted per part."""
        Vt, T = self.Vt, self.types
        for part in mesh.parts:
            if len(part.faces) == 0:
                continue
            used, faces = np.unique(part.faces, return_inverse=True)
            faces = faces.reshape(-1, 3)
            pts = points_y_up(mesh.positions[used])
            if offset is not None:
                pts = pts - offset
            m = self.prim(f"{parent}/{self.ident(part.material)}", "Mesh")
            self.attr(m, "subdivisionScheme", T.Token, "none", uniform=True)
            self.attr(m, "points", T.Point3fArray, Vt.Vec3fArray.FromNumpy(pts.astype(np.float32)))
            normals = self.attr(m, "normals", T.Normal3fArray, Vt.Vec3fArray.FromNumpy(
                points_y_up(mesh.normals[used]).astype(np.float32)))
            normals.SetInfo("interpolation", "vertex")  # after the value, as UsdGeom sets it
            self.attr(m, "faceVertexCounts", T.IntArray,
                      Vt.IntArray.FromNumpy(np.full(len(faces), 3, np.int32)))
            self.attr(m, "faceVertexIndices", T.IntArray,
                      Vt.IntArray.FromNumpy(faces.reshape(-1).astype(np.int32)))
            lo, hi = pts.min(axis=0), pts.max(axis=0)
            self.attr(m, "extent", T.Float3Array,
                      Vt.Vec3fArray.FromNumpy(np.stack([lo, hi]).astype(np.float32)))
            if part.double_sided:
                self.attr(m, "doubleSided", T.Bool, True, uniform=True)
            self.attr(m, "primvars:st", T.TexCoord2fArray,
                      Vt.Vec2fArray.FromNumpy(mesh.uvs[used].astype(np.float32)),
                      interpolation="vertex")
            self.apply(m, "MaterialBindingAPI")
            self.rel(m, "material:binding", self.material(part.shader, part.colour))
            if skel_path is not None:
                self.apply(m, "SkelBindingAPI")
                self.rel(m, "skel:skeleton", skel_path)
                w1 = mesh.weights[used, 1].astype(np.float32)
                weights = np.stack([np.float32(1.0) - w1, w1], 1)
                joints = mesh.joints[used].astype(np.int32)
                self.attr(m, "primvars:skel:jointIndices", T.IntArray,
                          Vt.IntArray.FromNumpy(joints.ravel()),
                          interpolation="vertex", elementSize=2)
                self.attr(m, "primvars:skel:jointWeights", T.FloatArray,
                          Vt.FloatArray.FromNumpy(weights.ravel()),
                          interpolation="vertex", elementSize=2)
                self.attr(m, "primvars:skel:geomBindTransform", T.Matrix4d, self.Gf.Matrix4d(1.0))

    def tree(self, i: int, mesh: TreeMesh, path: str | None = None) -> int:
        """Tree i at `path` (default: a child of the root named after it);
        the joints written."""
        t = self.bake.trees[i]
        if path is None:
            path = self.unique(self.root, t.name)
        if t.static:
            if path != self.root:
                self.prim(path, "Xform")
            self.meshes(path, mesh, None)
            return 0
        if path == self.root:  # a tree layer: its root is the SkelRoot
            self.layer.GetPrimAtPath(path).typeName = "SkelRoot"
        else:
            self.prim(path, "SkelRoot")
        self.skeleton(t, f"{path}/Skel")
        self.meshes(path, mesh, f"{path}/Skel")
        return t.n_segments

    def skeleton(self, t, path: str) -> None:
        """Tree `t`'s Skeleton at `path` (joints, bind and rest transforms)
        and its SkelAnimation `path`/Anim, sampled at the bake's frames and
        the sub-frame times where a joint turns fast."""
        Vt, Gf, T = self.Vt, self.Gf, self.types
        skel = self.prim(path, "Skeleton")
        names = joint_names(t.name, t.paths)
        tokens = Vt.TokenArray(joint_tokens(t.seg_parent, names))
        self.attr(skel, "joints", T.TokenArray, tokens, uniform=True)
        self.attr(skel, "jointNames", T.TokenArray, Vt.TokenArray(names), uniform=True)
        rest = points_y_up(t.points[t.seg_start]).astype(np.float64)
        S = t.n_segments
        bind = np.tile(np.eye(4), (S, 1, 1))
        bind[:, 3, :3] = rest  # Gf matrices are row-vector: translation in the last row
        self.attr(skel, "bindTransforms", T.Matrix4dArray, Vt.Matrix4dArray.FromNumpy(bind),
                  uniform=True)
        par = t.seg_parent
        local_rest = bind.copy()
        has = par >= 0
        local_rest[has, 3, :3] = rest[has] - rest[par[has]]
        self.attr(skel, "restTransforms", T.Matrix4dArray,
                  Vt.Matrix4dArray.FromNumpy(local_rest), uniform=True)
        self.attr(skel, "treebake:segmentPaths", T.StringArray, Vt.StringArray(list(t.paths)),
                  custom=True)
        anim = self.prim(f"{path}/Anim", "SkelAnimation")
        self.attr(anim, "joints", T.TokenArray, tokens, uniform=True)
        times, positions, rotations = t.samples(self.bake.times)
        # a skeleton's sub-frame codes hold every joint: one is kept where any
        # joint turns fast in that frame interval (TreeBake.fast_samples)
        kept = t.fast_samples(self.bake.times).any(axis=1)
        self.subframe_codes += int(kept.sum()) - len(self.bake.times)
        times, positions, rotations = times[kept], positions[kept], rotations[kept]
        pos = points_y_up(positions)
        rot = continuous(qnormalize(quats_y_up(rotations).astype(np.float64)), axis=0)
        t_loc, q_loc = local_transforms(par, pos, rot)
        q_loc = continuous(qnormalize(q_loc), axis=0).astype(np.float32)
        t_loc = t_loc.astype(np.float32)
        ta = self.attr(anim, "translations", T.Float3Array).path
        ra = self.attr(anim, "rotations", T.QuatfArray).path
        self.attr(anim, "scales", T.Half3Array, Vt.Vec3hArray(S, Gf.Vec3h(1.0, 1.0, 1.0)))
        layer = self.layer
        for f, code in enumerate(self.codes(times)):
            layer.SetTimeSample(ta, code, Vt.Vec3fArray.FromNumpy(t_loc[f]))
            layer.SetTimeSample(ra, code, Vt.QuatfArray.FromNumpy(q_loc[f]))
        self.apply(skel, "SkelBindingAPI")
        self.rel(skel, "skel:animationSource", f"{path}/Anim")

    def objects(self) -> None:
        o = self.bake.objects
        if o is None or not len(o.sizes):
            return
        Gf, T, layer = self.Gf, self.types, self.layer
        group = f"{self.root}/Projectiles"
        self.prim(group, "Xform")
        pos = points_y_up(o.positions).astype(np.float64)
        rot = continuous(qnormalize(quats_y_up(o.rotations).astype(np.float64)), axis=0)
        codes = self.codes(self.bake.times)
        for k, (shape, size) in enumerate(zip(o.shapes, o.sizes)):
            x = self.prim(f"{group}/projectile_{k}", "Xform")
            # as UsdGeomXformable.AddXformOp authors them: each op, then the order
            tr = self.attr(x, "xformOp:translate", T.Double3).path
            order = self.attr(x, "xformOpOrder", T.TokenArray,
                              self.Vt.TokenArray(["xformOp:translate"]), uniform=True)
            orient = self.attr(x, "xformOp:orient", T.Quatf).path
            order.default = self.Vt.TokenArray(["xformOp:translate", "xformOp:orient"])
            for f, code in enumerate(codes):
                layer.SetTimeSample(tr, code, Gf.Vec3d(*pos[f, k].tolist()))
                q = rot[f, k]
                layer.SetTimeSample(orient, code,
                                    Gf.Quatf(float(q[3]), float(q[0]), float(q[1]), float(q[2])))
            mesh = object_mesh(shape, float(size))
            for part in mesh.parts:
                part.colour = OBJECT_COLOUR
            self.meshes(f"{group}/projectile_{k}", mesh, None)

    def payload(self, prim: str, asset: str) -> None:
        """A typeless prim at `prim` whose payload is the layer `asset`."""
        spec = self.prim(prim)
        spec.payloadList.prependedItems.append(self.Sdf.Payload(asset))

    def codes(self, times: np.ndarray) -> list[float]:
        """USD time codes of sample times (s): frame numbers, fractional between."""
        return [float(c) for c in self.frame_start + np.asarray(times) * self.bake.fps]

    def save(self, path: Path) -> Path:
        """Write the layer to `path` atomically, in the format its extension
        asks (.usda text, .usd/.usdc binary crate): exported straight into
        the temporary file that is renamed over it."""
        with atomic_path(path, suffix=".tmp" + path.suffix) as tmp:
            try:
                written = self.layer.Export(str(tmp))
            except self.Tf.ErrorException as exc:  # as the OSError it is: a full disk named
                raise _write_error(exc, path) from None
            if not written:  # no error raised, yet not written: never an empty file renamed
                raise OSError(errno.EIO, "USD could not write the layer", str(path))
        return path


def _write_error(exc: Exception, path: Path) -> OSError:
    """USD's error writing the layer at `path` as an OSError naming it
    (ENOSPC where the disk was full, so that fileio reports it as such),
    with USD's first message."""
    text = str(exc)
    code = errno.ENOSPC if "No space left on device" in text else errno.EIO
    # USD's lines read "Error in 'FUNCTION' at line N in file F : 'MESSAGE'"
    first = next((line.rsplit(" : ", 1)[-1].strip().strip("'") for line in text.splitlines()
                  if line.strip()), "unknown error")
    return OSError(code, f"USD could not write the layer: {first}", str(path))


# validators that open every layer a stage depends on: on a root stage of
# payloads they would read the whole shot at once (193 MB per 100 MB of tree
# layers, measured); an unloaded root checks its payloads' files instead
OPEN_EVERY_LAYER = ("usdUtilsValidators:MissingReferenceValidator",
                    "usdUtilsValidators:UsdzPackageValidator")


def validate(path: str | Path, load: bool = True) -> list[str]:
    """Errors (not warnings) from every registered pxr.UsdValidation
    validator, as "name: message" strings. Empty = valid. `load`: with
    every payload loaded; else the stage as a DCC first opens it, without
    the validators that would open every payload's layer, and each
    payload's file checked to exist instead."""
    from pxr import Usd, UsdValidation

    stage = Usd.Stage.Open(str(path), Usd.Stage.LoadAll if load else Usd.Stage.LoadNone)
    reg = UsdValidation.ValidationRegistry()
    validators = [v for v in reg.GetOrLoadAllValidators()
                  if load or v.GetMetadata().name not in OPEN_EVERY_LAYER]
    ctx = UsdValidation.ValidationContext(validators)
    out = []
    for err in ctx.Validate(stage):
        if err.GetType() == UsdValidation.ValidationErrorType.Error:
            out.append(f"{err.GetName()}: {err.GetMessage()}")
    if not load:
        out += _missing_payloads(stage, Path(path).parent)
    return sorted(out)


def _missing_payloads(stage, folder: Path) -> list[str]:
    """A payload whose layer file is not there, as an error string."""
    out = []
    for prim in stage.TraverseAll():
        if not prim.HasPayload():
            continue
        for payload in prim.GetMetadata("payload").GetAddedOrExplicitItems():
            if not (folder / payload.assetPath).is_file():
                out.append(f"MissingPayload: {prim.GetPath()}: {payload.assetPath} not found")
    return out


@dataclass(frozen=True)
class LayerTask:
    """One tree's payload layer to write: tree `index`, its prim's name
    under the root, whether the layer is validated on its own."""

    index: int
    prim: str
    check: bool


@dataclass
class TreeLayer:
    """A tree's payload layer as written: its file, the joints written,
    sub-frame time codes, validation errors ("file: name: message")."""

    file: Path
    joints: int
    subframe_codes: int
    errors: list[str]


@dataclass(frozen=True)
class LayerSpec:
    """Where and how tree layers are written: `out`/`name`.trees/, the
    extension (.usd or .usda), the first frame's number, the textures
    (paths relative to a tree layer)."""

    out: Path
    name: str
    ext: str
    frame_start: int
    maps: dict

    @property
    def folder(self) -> str:
        return f"{self.name}.trees"


def write_tree_layer(bake: Bake, mesh: TreeMesh, task: LayerTask, spec: LayerSpec) -> TreeLayer:
    """Tree task.index of `bake` with its `mesh` as a component layer of its
    own (out/name.trees/PRIM.usd), validated if the task says so. Depends
    only on the tree: any process writes the same bytes."""
    tw = _Writer(bake, task.prim, spec.frame_start, spec.maps, kind="component")
    joints = tw.tree(task.index, mesh, tw.root)
    layer = spec.out / spec.folder / f"{task.prim}{spec.ext}"
    written = tw.save(layer)
    errors = [f"{layer.name}: {e}" for e in validate(layer)] if task.check else []
    return TreeLayer(written, joints, tw.subframe_codes, errors)


LayerWriter = Callable[[list[LayerTask], LayerSpec], Iterable[TreeLayer]]


def export_usd(bake: Bake, meshes: Sequence[TreeMesh], out: str | Path, name: str,
               ascii: bool = False, check: bool = True,
               progress: Callable[[int, int], None] | None = None,
               frame_start: int = 1,
               maps: dict[str, TextureMap] | None = None,
               layers: str = "one", write_layers: LayerWriter | None = None) -> UsdResult:
    """Write `out/name.usd` (binary crate) or `out/name.usda` (text); bake
    frame f at time code frame_start + f; `maps`: material -> its
    TextureMap (paths relative to the file) for the preview surfaces.
    `layers`: "one", the whole shot in that file; "tree", that file is a
    root stage whose trees are payloads, one layer per tree in
    `out/name.trees/` (a DCC opens the stage at once and loads trees on
    demand; memory follows one tree), written in this process or by
    `write_layers(tasks, spec)`, which yields their TreeLayers in the
    tasks' order (worker processes: export_pool.py): the same bytes."""
    if layers not in ("one", "tree"):
        raise ValueError(f"layers must be 'one' or 'tree', got {layers!r}")
    ext = ".usda" if ascii else ".usd"
    w = _Writer(bake, name, frame_start, maps)
    result = UsdResult(time_codes=(float(frame_start), float(frame_start + len(bake.times) - 1)))
    if layers == "one":
        for i, mesh in enumerate(meshes):
            result.joints += w.tree(i, mesh)
            if progress is not None:
                progress(i + 1, len(meshes))
    else:
        checked = _layers_checked(len(meshes)) if check else set()
        _tree_layers(w, bake, meshes, checked, write_layers, progress, result,
                     LayerSpec(Path(out), name, ext, frame_start, _from_subfolder(maps)))
    w.objects()
    result.subframe_codes += w.subframe_codes
    path = Path(out) / f"{name}{ext}"
    result.files.append(w.save(path))
    if check:
        result.validation_errors += validate(path, load=layers == "one")
        result.layers_checked = len(checked) if layers == "tree" else 0
    return result


def _from_subfolder(maps: dict[str, TextureMap] | None) -> dict[str, TextureMap]:
    """Texture paths for a tree layer, one folder down: they climb out of it."""
    return {m: TextureMap(f"../{t.path}", t.cutout, None if t.normal is None else f"../{t.normal}")
            for m, t in (maps or {}).items()}


def _tree_layers(w: _Writer, bake: Bake, meshes: Sequence[TreeMesh], checked: set[int],
                 write_layers: LayerWriter | None, progress, result: UsdResult,
                 spec: LayerSpec) -> None:
    """Every tree's payload layer written (here or by `write_layers`) and
    added to the root stage of `w` as a payload, in the trees' order."""
    prims = [w.unique(w.root, tree_info(bake.trees, i)["name"]) for i in range(len(meshes))]
    tasks = [LayerTask(i, prim.rsplit("/", 1)[1], i in checked) for i, prim in enumerate(prims)]
    if write_layers is None:
        written = (write_tree_layer(bake, meshes[t.index], t, spec) for t in tasks)
    else:
        written = write_layers(tasks, spec)
    for k, (prim, layer) in enumerate(zip(prims, written, strict=True), 1):
        result.joints += layer.joints
        result.subframe_codes += layer.subframe_codes
        result.files.append(layer.file)
        result.validation_errors += layer.errors
        w.payload(prim, f"./{spec.folder}/{layer.file.name}")
        if progress is not None:
            progress(k, len(meshes))


LAYERS_CHECKED = 20  # tree layers validated on their own, at most, spread over the shot


def _layers_checked(trees: int) -> set[int]:
    """Which tree layers an export validates: all of a small shot, else
    LAYERS_CHECKED of them spread evenly, the first and last included."""
    if trees <= LAYERS_CHECKED:
        return set(range(trees))
    return {round(k * (trees - 1) / (LAYERS_CHECKED - 1)) for k in range(LAYERS_CHECKED)}
