"""OpenUSD's own writing and reading of 3D Gaussian splats (usd-core, pinned in
requirements-usd.txt), for splat-io's USD tests in tests/tests/formats.rs.

    python usd.py write SOURCE.ply OUT_DIR
        usd-core.usda: the source's splats as 3dgrut's exporter writes them (UsdVol's
        ParticleField3DGaussianSplat at /World/Gaussians/gaussians: linear scales, opacities
        after the sigmoid, quaternions (w, x, y, z), SH coefficients DC first with elementSize
        (d + 1)^2, ColorSpaceAPI srgb_rec709_display); usd-core-placed.usda: the same under an
        Xform with translate, pivot, rotateXYZ, orient, a mirroring scale and a transform op;
        usd-core-placed.json: usd-core's world matrix of that prim.
    python usd.py dump IN.usda OUT.json
        every ParticleField3DGaussianSplat prim of IN as usd-core reads it: path, attributes,
        elementSize, world matrix.
"""
import json
import math
import os
import struct
import sys

from pxr import Gf, Sdf, Usd, UsdGeom, UsdVol, Vt

SPLAT_TYPE = "ParticleField3DGaussianSplat"


def read_ply(path):
    """A binary little-endian 3DGS .ply of float properties: (names, rows)."""
    data = open(path, "rb").read()
    end = data.index(b"end_header\n") + len(b"end_header\n")
    names, count = [], 0
    for line in data[:end].decode().splitlines():
        words = line.split()
        if words[:2] == ["element", "vertex"]:
            count = int(words[2])
        elif words[:2] == ["property", "float"]:
            names.append(words[2])
    rows = list(struct.iter_unpack("<%df" % len(names), data[end:end + 4 * len(names) * count]))
    return names, rows


def splat_stage(names, rows):
    """A stage laid out as 3dgrut's exporter lays one out, holding the .ply's splats."""
    col = {n: i for i, n in enumerate(names)}
    rest = sum(1 for n in names if n.startswith("f_rest_")) // 3
    degree = int(round(math.sqrt(rest + 1))) - 1
    stage = Usd.Stage.CreateInMemory()
    stage.SetMetadata("metersPerUnit", 1.0)
    stage.SetMetadata("upAxis", "Y")
    UsdGeom.Xform.Define(stage, "/World")
    stage.SetMetadata("defaultPrim", "World")
    root = UsdGeom.Xform.Define(stage, "/World/Gaussians")
    splats = UsdVol.ParticleField3DGaussianSplat.Define(stage, "/World/Gaussians/gaussians")
    get = lambda r, n: r[col[n]]
    positions, orientations, scales, opacities, coefficients = [], [], [], [], []
    for r in rows:
        positions.append(Gf.Vec3f(get(r, "x"), get(r, "y"), get(r, "z")))
        q = [get(r, "rot_%d" % i) for i in range(4)]
        norm = math.sqrt(sum(c * c for c in q))
        orientations.append(Gf.Quatf(*(c / norm for c in q)))
        scales.append(Gf.Vec3f(*(math.exp(get(r, "scale_%d" % i)) for i in range(3))))
        opacities.append(1.0 / (1.0 + math.exp(-get(r, "opacity"))))
        coefficients.append(Gf.Vec3f(get(r, "f_dc_0"), get(r, "f_dc_1"), get(r, "f_dc_2")))
        for k in range(rest):
            coefficients.append(Gf.Vec3f(*(get(r, "f_rest_%d" % (c * rest + k)) for c in range(3))))
    splats.CreatePositionsAttr().Set(Vt.Vec3fArray(positions))
    splats.CreateOrientationsAttr().Set(Vt.QuatfArray(orientations))
    splats.CreateScalesAttr().Set(Vt.Vec3fArray(scales))
    splats.CreateOpacitiesAttr().Set(Vt.FloatArray(opacities))
    splats.CreateRadianceSphericalHarmonicsDegreeAttr().Set(degree)
    sh = splats.CreateRadianceSphericalHarmonicsCoefficientsAttr()
    sh.Set(Vt.Vec3fArray(coefficients))
    sh.SetMetadata("elementSize", (degree + 1) ** 2)
    splats.CreateProjectionModeHintAttr().Set("perspective")
    splats.CreateSortingModeHintAttr().Set("cameraDistance")
    Usd.ColorSpaceAPI.Apply(splats.GetPrim()).CreateColorSpaceNameAttr().Set("srgb_rec709_display")
    lo = [min(p[i] for p in positions) for i in range(3)]
    hi = [max(p[i] for p in positions) for i in range(3)]
    splats.CreateExtentAttr().Set(Vt.Vec3fArray([Gf.Vec3f(*lo), Gf.Vec3f(*hi)]))
    return stage, root, splats


def world_rows(prim):
    m = UsdGeom.Xformable(prim).ComputeLocalToWorldTransform(Usd.TimeCode.Default())
    return [[m[r][c] for c in range(4)] for r in range(4)]


def write(source, out):
    names, rows = read_ply(source)
    stage, _, _ = splat_stage(names, rows)
    stage.GetRootLayer().Export(os.path.join(out, "usd-core.usda"))
    stage, root, splats = splat_stage(names, rows)
    root.AddTranslateOp().Set(Gf.Vec3d(1.0, -2.0, 3.0))
    root.AddTranslateOp(opSuffix="pivot").Set(Gf.Vec3f(0.5, 0.25, -0.5))
    root.AddRotateXYZOp().Set(Gf.Vec3f(10.0, 20.0, 30.0))
    root.AddOrientOp().Set(Gf.Quatf(0.9, 0.1, -0.3, 0.2).GetNormalized())
    root.AddScaleOp().Set(Gf.Vec3f(1.5, -1.5, 1.5))
    root.AddTranslateOp(opSuffix="pivot", isInverseOp=True)
    root.AddTransformOp(opSuffix="extra").Set(Gf.Matrix4d().SetRotate(Gf.Rotation(Gf.Vec3d(0, 1, 1), 40)))
    stage.GetRootLayer().Export(os.path.join(out, "usd-core-placed.usda"))
    with open(os.path.join(out, "usd-core-placed.json"), "w") as f:
        json.dump({"world": world_rows(splats.GetPrim())}, f)


def flat(values, arity):
    out = []
    for v in values:
        if arity == 4:
            out.extend([v.GetReal(), *v.GetImaginary()])
        elif arity == 1:
            out.append(v)
        else:
            out.extend(v)
    return out


def dump(path, out):
    stage = Usd.Stage.Open(path)
    prims = []
    for prim in stage.Traverse():
        if prim.GetTypeName() != SPLAT_TYPE:
            continue
        splats = UsdVol.ParticleField3DGaussianSplat(prim)
        sh = splats.GetRadianceSphericalHarmonicsCoefficientsAttr()
        prims.append({
            "path": str(prim.GetPath()),
            "is_a": prim.IsA(UsdVol.ParticleField3DGaussianSplat),
            "applied": [str(s) for s in prim.GetAppliedSchemas()],
            "positions": flat(splats.GetPositionsAttr().Get(), 3),
            "orientations": flat(splats.GetOrientationsAttr().Get(), 4),
            "scales": flat(splats.GetScalesAttr().Get(), 3),
            "opacities": flat(splats.GetOpacitiesAttr().Get(), 1),
            "degree": splats.GetRadianceSphericalHarmonicsDegreeAttr().Get(),
            "coefficients": flat(sh.Get(), 3),
            "element_size": sh.GetMetadata("elementSize"),
            "color_space": Usd.ColorSpaceAPI(prim).GetColorSpaceNameAttr().Get(),
            "world": world_rows(prim),
        })
    with open(out, "w") as f:
        json.dump({"prims": prims}, f)


if __name__ == "__main__":
    {"write": write, "dump": dump}[sys.argv[1]](sys.argv[2], sys.argv[3])
