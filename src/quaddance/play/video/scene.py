"""The model as the video draws it: which model (`ModelSource`), its copy edited for drawing
only (`simplify_meshes`, `finite_planes`), and `FrameRenderer`, which draws a pose of it.

The edits make software rendering fast enough (640x480 on 2 cores): the Go1's 206 k-triangle
visual meshes are simplified by vertex clustering, which looks the same at this size and
renders several times faster on llvmpipe, and the infinite floor is drawn as a finite one
with fewer quads. They are made in the render workers' private model copies, never in a model
that is simulated.
"""

from __future__ import annotations

from collections.abc import Callable

import mujoco
import numpy as np

from quaddance.errors import QuaddanceError
from quaddance.play.video.config import RenderCfg
from quaddance.robots import RobotCfg

ModelSource = mujoco.MjModel | Callable[[], mujoco.MjModel] | None
"""A model to render, or a zero-argument function that builds one; None means the dance scene
of `RenderCfg.robot` with its visual meshes (`quaddance.sim.scene.build_model(visual=True)`)."""


def default_model(robot: RobotCfg) -> mujoco.MjModel:
    """The dance scene of ``robot`` with its visual meshes."""
    from quaddance.sim.scene import SceneCfg, build_model

    return build_model(SceneCfg(robot=robot), visual=True)


def load_model(model: ModelSource, robot: RobotCfg) -> mujoco.MjModel:
    """The model that ``model`` names (built now if it is a function, or ``robot``'s scene if
    it is None)."""
    if model is None:
        return default_model(robot)
    if isinstance(model, mujoco.MjModel):
        return model
    if callable(model):
        return model()
    raise QuaddanceError(f"model must be an MjModel or a function that builds one, got {model!r}")


def simplify_meshes(model: mujoco.MjModel, cell_m: float) -> int:
    """Simplify every mesh of ``model`` in place by vertex clustering, for drawing only.

    Vertices in the same ``cell_m`` cube merge into their centroid; triangles that collapse
    are dropped. The kept triangles are written to the front of each mesh's face block and
    ``mesh_facenum`` shrinks, which is all the renderer reads when it uploads the meshes.
    Use only on a model copy that is drawn, never simulated (mesh collision data is stale).

    Returns:
        Number of triangles left, summed over meshes.
    """
    total = 0
    for i in range(model.nmesh):
        vadr, vnum = int(model.mesh_vertadr[i]), int(model.mesh_vertnum[i])
        fadr, fnum = int(model.mesh_faceadr[i]), int(model.mesh_facenum[i])
        if vnum == 0 or fnum == 0:
            continue
        verts = model.mesh_vert[vadr : vadr + vnum]
        faces = model.mesh_face[fadr : fadr + fnum].copy()
        cells = np.floor(verts / cell_m).astype(np.int64)
        cells -= cells.min(axis=0)
        dims = cells.max(axis=0) + 1
        keys = (cells[:, 0] * dims[1] + cells[:, 1]) * dims[2] + cells[:, 2]  # one int per cell
        _, first, cluster = np.unique(keys, return_index=True, return_inverse=True)
        centroid = np.zeros((len(first), 3))
        np.add.at(centroid, cluster, verts)
        centroid /= np.bincount(cluster)[:, None]
        verts[first] = centroid  # each cluster is drawn at its first vertex, moved to the centroid
        merged = first[cluster][faces]
        keep = (
            (merged[:, 0] != merged[:, 1])
            & (merged[:, 1] != merged[:, 2])
            & (merged[:, 0] != merged[:, 2])
        )
        n_keep = int(keep.sum())
        # Normals and texture coordinates stay those of the original corners: close enough.
        normals = model.mesh_facenormal[fadr : fadr + fnum][keep].copy()
        model.mesh_face[fadr : fadr + n_keep] = merged[keep]
        model.mesh_facenormal[fadr : fadr + n_keep] = normals
        if model.mesh_texcoordnum[i] > 0:
            texcoords = model.mesh_facetexcoord[fadr : fadr + fnum][keep].copy()
            model.mesh_facetexcoord[fadr : fadr + n_keep] = texcoords
        model.mesh_facenum[i] = n_keep
        total += n_keep
    return total


def finite_planes(model: mujoco.MjModel, half_size_m: float, grid_m: float) -> int:
    """Make every infinite plane of ``model`` (size 0) a finite square, for drawing only.

    Its texture keeps its size on the floor: an infinite plane's material repeats
    ``texrepeat`` times per metre, as a finite plane's does with ``texuniform`` set (set
    only on a material that no other kind of geom uses).

    Returns:
        Number of planes changed.
    """
    changed = 0
    plane = model.geom_type == mujoco.mjtGeom.mjGEOM_PLANE
    for g in np.flatnonzero(plane):
        if model.geom_size[g, 0] > 0 and model.geom_size[g, 1] > 0:
            continue
        model.geom_size[g] = (half_size_m, half_size_m, grid_m)
        mat = model.geom_matid[g]
        if mat >= 0 and not np.any(model.geom_matid[~plane] == mat):
            model.mat_texuniform[mat] = 1
        changed += 1
    return changed


class FrameRenderer:
    """Draws poses of one model to RGB arrays. Create it only in a process using EGL."""

    def __init__(self, model: mujoco.MjModel, width: int, height: int, cfg: RenderCfg) -> None:
        self.model = model
        self.cfg = cfg
        model.vis.global_.offwidth = max(width, int(model.vis.global_.offwidth))
        model.vis.global_.offheight = max(height, int(model.vis.global_.offheight))
        model.vis.quality.offsamples = cfg.msaa_samples
        if cfg.mesh_cell_m:
            simplify_meshes(model, cfg.mesh_cell_m)
        if cfg.floor_half_size_m:
            finite_planes(model, cfg.floor_half_size_m, cfg.floor_grid_m)
        self.data = mujoco.MjData(model)
        self.renderer = mujoco.Renderer(model, height, width)
        flags = self.renderer.scene.flags
        flags[mujoco.mjtRndFlag.mjRND_SHADOW] = cfg.shadows
        flags[mujoco.mjtRndFlag.mjRND_REFLECTION] = cfg.reflections
        self.option = mujoco.MjvOption()
        if model.nmesh == 0:
            # A physics-only model (no visual meshes): show the collision shapes instead.
            self.option.geomgroup[3] = 1
        if cfg.camera is not None:
            if mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_CAMERA, cfg.camera) < 0:
                raise QuaddanceError(f"the model has no camera named {cfg.camera!r}")
            self.camera: mujoco.MjvCamera | str = cfg.camera
        else:
            cam = mujoco.MjvCamera()
            cam.type = mujoco.mjtCamera.mjCAMERA_FREE
            cam.distance = cfg.distance_m
            cam.azimuth = cfg.azimuth_deg
            cam.elevation = cfg.elevation_deg
            self.camera = cam
        self.front_sites = [
            mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, name)
            for name in cfg.robot.foot_sites[:2]
        ]

    def render(
        self,
        qpos: np.ndarray,
        lookat: np.ndarray | None = None,
        target_heights_m: np.ndarray | None = None,
        out: np.ndarray | None = None,
    ) -> np.ndarray:
        """One frame, (height, width, 3) uint8.

        Args:
            qpos: (nq,) pose.
            lookat: (3,) follow-camera look-at point, m; ignored with a named camera.
            target_heights_m: (4,) targets (FL, FR, RL, RR), m: draws the front-foot markers.
            out: (height, width, 3) uint8 array to draw into (returned); None: a new one.
        """
        self.data.qpos[:] = qpos
        mujoco.mj_forward(self.model, self.data)
        if isinstance(self.camera, mujoco.MjvCamera) and lookat is not None:
            self.camera.lookat[:] = lookat
        self.renderer.update_scene(self.data, camera=self.camera, scene_option=self.option)
        if target_heights_m is not None:
            self._add_markers(np.asarray(target_heights_m, dtype=float))
        return self.renderer.render(out=out)

    def _add_markers(self, target_heights_m: np.ndarray) -> None:
        scene = self.renderer.scene
        for foot, site in enumerate(self.front_sites):
            if site < 0 or scene.ngeom >= scene.maxgeom or not np.isfinite(target_heights_m[foot]):
                continue
            pos = self.data.site_xpos[site].copy()
            # The foot site is the centre of the foot sphere, whose bottom is the foot height.
            pos[2] = target_heights_m[foot] + self.cfg.robot.foot_radius_m
            mujoco.mjv_initGeom(
                scene.geoms[scene.ngeom],
                mujoco.mjtGeom.mjGEOM_SPHERE,
                np.array([self.cfg.marker_radius_m, 0.0, 0.0]),
                pos,
                np.eye(3).reshape(-1),
                np.asarray(self.cfg.marker_rgba[foot], dtype=np.float32),
            )
            scene.ngeom += 1
