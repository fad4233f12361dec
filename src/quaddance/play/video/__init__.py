"""Headless video of a rollout, with the song as its soundtrack.

Frames are rendered on the CPU by MuJoCo's `mujoco.Renderer` through EGL and Mesa's software
rasteriser (llvmpipe; Debian packages libegl1, libegl-mesa0, libgl1-mesa-dri). OSMesa is not
used: it crashed in processes that had imported torch.

- `config`: frame rate, look, camera and encoder settings (`RenderCfg`), `RenderError`.
- `scene`: the model as drawn: simplified meshes and a finite floor in the workers' private
  copies (what makes 640x480 on 2 cores fast enough, with shadows, reflections and
  multisampling off), and `FrameRenderer`, which draws one pose.
- `poses`: the pose of each frame and the follow camera's smoothed path.
- `workers`: the rendering processes (spawned, lower priority) and the shared-memory frame
  slots they draw into (`WorkerPool`).
- `encode`: one ffmpeg that encodes the frames in order and muxes the song (`RenderTask`).
- `renderer`: `VideoRenderer`, which streams poses into a video while the dance is simulated,
  and `render_video`.
- `stills`: PNG stills (`write_frames_png`).
"""

from quaddance.play.video.config import VIDEO_FPS, RenderCfg, RenderError
from quaddance.play.video.encode import RenderTask, video_info
from quaddance.play.video.poses import QposLayout, follow_lookat, resample_qpos
from quaddance.play.video.renderer import VideoRenderer, VideoStream, render_video
from quaddance.play.video.scene import ModelSource, finite_planes, simplify_meshes
from quaddance.play.video.stills import write_frames_png

__all__ = [
    "VIDEO_FPS",
    "ModelSource",
    "QposLayout",
    "RenderCfg",
    "RenderError",
    "RenderTask",
    "VideoRenderer",
    "VideoStream",
    "finite_planes",
    "follow_lookat",
    "render_video",
    "resample_qpos",
    "simplify_meshes",
    "video_info",
    "write_frames_png",
]
