"""The video's settings: frame rate, look, camera and encoder (`RenderCfg`), and its errors."""

from __future__ import annotations

from dataclasses import dataclass

from quaddance.errors import QuaddanceError
from quaddance.robots import GO1, RobotCfg

VIDEO_FPS = 25.0
"""Frame rate of the videos, Hz. 25 divides the 50 Hz policy rate (each frame is a simulated
pose, none interpolated) and draws a sixth fewer frames than 30: rendering is most of the
`dance` command's CPU time on 2 cores (`quaddance bench dance`)."""

EGL_PACKAGES = "libegl1 libegl-mesa0 libgl1-mesa-dri"
"""Debian packages that headless EGL rendering on the CPU needs."""


@dataclass(frozen=True)
class RenderCfg:
    """Look, camera and encoder settings of the video."""

    #: The robot drawn: its scene when no model is given, its front feet for the markers.
    robot: RobotCfg = GO1
    #: Named model camera (e.g. "tracking") instead of the smoothed follow camera.
    camera: str | None = None
    #: Follow camera: distance to the look-at point, m. Frames the 0.65 m Go1 with room for
    #: raised legs at MuJoCo's default 45 degree field of view (chosen by eye).
    distance_m: float = 1.3
    #: Follow camera direction of view, degrees: 225 looks from the robot's front-left
    #: (+x, +y) back towards it, a 3/4 view of the front legs.
    azimuth_deg: float = 225.0
    elevation_deg: float = -15.0
    #: Look-at point relative to the base position, m (a bit below the trunk, so both the
    #: body and the feet stay in the frame).
    lookat_offset_m: tuple[float, float, float] = (0.0, 0.0, -0.08)
    #: Gaussian smoothing of the look-at path, s, so the camera does not shake with the trunk.
    smooth_s: float = 0.4
    #: Vertex-clustering cell for the visual meshes, m; None keeps the full meshes.
    #: 8 mm: 18 % faster than 4 mm (about one pixel at 640x480 and 1.3 m) and looks the
    #: same at that size; 16 mm shows facets (all measured; the full meshes have 206 k
    #: triangles).
    mesh_cell_m: float | None = 0.008
    #: An infinite floor plane is drawn as this finite square (half size, m) with quads of
    #: ``floor_grid_m``. MuJoCo draws an infinite plane with up to 200 x 200 quads
    #: (mjMAXPLANEGRID): 30 ms of llvmpipe's time per 640x480 frame, against 20 ms for 30 m
    #: with 0.5 m quads, which looks the same except for the haze line at the horizon
    #: (measured; 1.4 of 255 mean difference below it). None keeps infinite planes.
    floor_half_size_m: float | None = 30.0
    floor_grid_m: float = 0.5
    #: Off-screen multisampling; 0 halves llvmpipe's cost (measured 6.6 -> 12.6 frames/s).
    msaa_samples: int = 0
    shadows: bool = False  # 1.6 vs 10.4 frames/s measured with shadows and reflections on/off
    reflections: bool = False
    #: Target markers: translucent spheres above the front feet.
    marker_radius_m: float = 0.025
    marker_rgba: tuple[tuple[float, float, float, float], ...] = (
        (1.0, 0.55, 0.1, 0.55),  # FL orange, as in the plots
        (0.15, 0.55, 1.0, 0.55),  # FR blue
    )
    #: H.264 settings: encoding shares the cores with the software renderer, so the cheapest
    #: preset. 300 frames of a dance at 640x480: "veryfast" crf 20 took 2.1 s CPU (0.6 MB),
    #: "ultrafast" crf 23 0.9 s (1.9 MB), PSNR 43 dB between the two (measured).
    crf: int = 23
    preset: str = "ultrafast"
    #: x264 threads: 1 took 4.3 s CPU for 900 frames, x264's own choice 4.8 s, same file
    #: size (measured); the render workers keep the cores busy anyway.
    encoder_threads: int = 1
    audio_bitrate: str = "160k"
    #: ffmpeg's AAC search: "fast" took 0.44 s CPU for the 30 s demo song, the default
    #: "twoloop" 1.04 s (measured); the soundtrack of a robot video needs no more.
    aac_coder: str = "fast"


class RenderError(QuaddanceError):
    """Rendering failed in a worker; ``worker_traceback`` holds the worker's traceback."""

    def __init__(self, message: str, worker_traceback: str = "") -> None:
        super().__init__(message)
        self.worker_traceback = worker_traceback


def check_size(width: int, height: int, fps: float) -> None:
    """Refuse a frame size that H.264 in yuv420p cannot take (odd) or a tiny one, and fps <= 0."""
    if width < 16 or height < 16 or width % 2 or height % 2:
        raise QuaddanceError(f"video size must be even and at least 16x16, got {width}x{height}")
    if not fps > 0:
        raise QuaddanceError(f"fps must be > 0, got {fps}")
