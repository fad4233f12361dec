"""Playback: closed-loop rollout of a policy, and its outputs (video with music, plots, metrics).

- `rollout.py`: run a trained policy on a dance in native MuJoCo.
- `video.py`: headless rendering (EGL + Mesa) in worker processes, muxed with the song.
- `plots.py`: the paper's Fig. 4 (target vs measured foot heights) and the eval report.
- `metrics.py`: tracking error, correlation, rear-foot lift and the beat align score (BAS).
"""
