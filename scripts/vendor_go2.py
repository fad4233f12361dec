"""Vendor the Unitree Go2 model into quaddance/data/robots/unitree_go2 (run once, by hand).

Source: Unitree's own MuJoCo model, `unitree_robots/go2` of github.com/unitreerobotics/
unitree_mujoco (BSD-3-Clause, its LICENSE is copied beside the model), the same model as
MuJoCo Menagerie's `unitree_go2`. A fresh machine cannot reach GitHub, so the result is
committed; this script records how it was made:

    python scripts/vendor_go2.py /path/to/unitree_mujoco

What changes from the source, and why:
- The visual meshes are simplified by vertex clustering (1 mm cells) and stored as binary
  STL: 20 MB of OBJ become about 3 MB, and they only draw the video. `base_4.obj` (the
  trunk's grey shell) is not in the mirror this was made from: a grey box of the trunk's
  collision size stands in for it.
- Collision geometry is the source's primitives (boxes, cylinders, spheres), named as
  quaddance's robot config reads them (`*_collision`, feet `FL_foot_collision`...), and a
  site at each foot sphere's centre named after its leg.
- The elliptic friction cones and impratio 100 are reset to MuJoCo's defaults (the Go1's).
- The motors, the keyframe and the joints' passive damping and friction loss are removed:
  quaddance adds its own PD position actuators and armature (`quaddance.sim.scene`), as it
  does for mjlab's Go1, whose model has none either.
"""

from __future__ import annotations

import argparse
import shutil
import struct
import xml.etree.ElementTree as ET
from pathlib import Path

import mujoco
import numpy as np

OUT = Path(__file__).resolve().parents[1] / "src/quaddance/data/robots/unitree_go2"
CELL_M = 0.001


def read_obj(path: Path) -> tuple[np.ndarray, np.ndarray]:
    verts: list[list[float]] = []
    faces: list[list[int]] = []
    for line in path.read_text(errors="replace").splitlines():
        parts = line.split()
        if not parts:
            continue
        if parts[0] == "v":
            verts.append([float(x) for x in parts[1:4]])
        elif parts[0] == "f":
            idx = [int(p.split("/")[0]) - 1 for p in parts[1:]]
            faces += [[idx[0], idx[i], idx[i + 1]] for i in range(1, len(idx) - 1)]
    return np.asarray(verts), np.asarray(faces, dtype=np.int64)


def cluster(verts: np.ndarray, faces: np.ndarray, cell_m: float) -> tuple[np.ndarray, np.ndarray]:
    """Vertex clustering: every vertex moves to the mean of its grid cell; faces that collapse
    are dropped, and so are repeated faces."""
    keys = np.floor(verts / cell_m).astype(np.int64)
    _, inverse = np.unique(keys, axis=0, return_inverse=True)
    inverse = inverse.reshape(-1)
    counts = np.bincount(inverse)
    merged = np.zeros((counts.size, 3))
    np.add.at(merged, inverse, verts)
    merged /= counts[:, None]
    tri = inverse[faces]
    keep = (tri[:, 0] != tri[:, 1]) & (tri[:, 1] != tri[:, 2]) & (tri[:, 0] != tri[:, 2])
    tri = tri[keep]
    _, first = np.unique(np.sort(tri, axis=1), axis=0, return_index=True)
    return merged, tri[np.sort(first)]


def write_stl(path: Path, verts: np.ndarray, faces: np.ndarray) -> None:
    tri = verts[faces].astype(np.float32)
    normals = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    normals /= np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), 1e-12)
    with path.open("wb") as f:
        f.write(b"quaddance go2 visual mesh".ljust(80, b" "))
        f.write(struct.pack("<I", len(faces)))
        for n, t in zip(normals.astype(np.float32), tri, strict=True):
            f.write(n.tobytes() + t.tobytes() + b"\0\0")


def _legs_in_go1_order(path: Path) -> None:
    """The source lists the legs FL, FR, RL, RR; reorder them FR, FL, RR, RL, the order of
    the Go1 model and of both SDKs' motors, so that joint and motor order agree."""
    tree = ET.parse(path)
    base = tree.getroot().find("./worldbody/body[@name='base']")
    assert base is not None
    hips = {b.get("name"): b for b in base.findall("body")}
    for body in hips.values():
        base.remove(body)
    for name in ("FR_hip", "FL_hip", "RR_hip", "RL_hip"):
        base.append(hips[name])
    ET.indent(tree, space="  ")
    tree.write(path, encoding="unicode")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("unitree_mujoco", type=Path, help="a checkout of unitree_mujoco")
    args = parser.parse_args()
    src = args.unitree_mujoco / "unitree_robots/go2"
    OUT.mkdir(parents=True, exist_ok=True)
    (OUT / "assets").mkdir(exist_ok=True)

    spec = mujoco.MjSpec.from_file(str(src / "go2.xml"))
    for actuator in list(spec.actuators):
        spec.delete(actuator)
    for key in list(spec.keys):
        spec.delete(key)
    # MuJoCo's default contact model, as the Go1's: the source's elliptic cones with
    # impratio 100 made the robot jump off the floor under quaddance's contact settings.
    spec.option.cone = mujoco.mjtCone.mjCONE_PYRAMIDAL
    spec.option.impratio = 1.0
    for joint in spec.joints:
        joint.damping = np.zeros(3)
        joint.frictionloss = 0.0
    missing = [m for m in spec.meshes if not (src / "assets" / m.file).is_file()]
    missing_names = {m.name or Path(m.file).stem for m in missing}
    for geom in list(spec.geoms):
        if geom.type == mujoco.mjtGeom.mjGEOM_MESH and geom.meshname in missing_names:
            spec.delete(geom)
    for mesh in missing:
        spec.delete(mesh)
    if "base_4" in missing_names:
        # The grey shell of the trunk: a box the size of the trunk's collision box stands in.
        trunk = spec.body("base_link")
        box = next(g for g in trunk.geoms if g.type == mujoco.mjtGeom.mjGEOM_BOX)
        trunk.add_geom(
            type=mujoco.mjtGeom.mjGEOM_BOX,
            size=box.size,
            pos=box.pos,
            material="gray",
            contype=0,
            conaffinity=0,
            group=2,
            name="base_shell",
        )
    for mesh in spec.meshes:
        verts, faces = read_obj(src / "assets" / mesh.file)
        verts, faces = cluster(verts, faces, CELL_M)
        stl = Path(mesh.file).with_suffix(".stl").name
        write_stl(OUT / "assets" / stl, verts, faces)
        mesh.name = mesh.name or Path(mesh.file).stem
        mesh.file = stl

    spec.body("base_link").name = "base"
    for body in spec.bodies:
        counter = 0
        for geom in body.geoms:
            if geom.classname.name == "foot":
                geom.name = f"{geom.name}_foot_collision"
                body.add_site(name=geom.name.removesuffix("_foot_collision"), pos=geom.pos)
            elif geom.contype != 0 or geom.conaffinity != 0:
                if geom.type == mujoco.mjtGeom.mjGEOM_MESH:
                    continue
                counter += 1
                geom.name = f"{body.name}_collision{counter}"
    spec.modelname = "go2"
    spec.meshdir = str(OUT / "assets")  # to_xml compiles, so the meshes must be found
    (OUT / "go2.xml").write_text(spec.to_xml().replace(str(OUT / "assets"), "assets"))
    _legs_in_go1_order(OUT / "go2.xml")
    mujoco.MjModel.from_xml_path(str(OUT / "go2.xml"))  # check that it builds
    shutil.copy(args.unitree_mujoco / "LICENSE", OUT / "LICENSE")
    print(f"wrote {OUT} ({sum(p.stat().st_size for p in OUT.rglob('*') if p.is_file())} bytes)")


if __name__ == "__main__":
    main()
