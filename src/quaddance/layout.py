"""What every stage agrees on about a dance's numbers: the columns of a target row, the rates,
the target modes and the meter. It imports nothing (no numpy, no torch, no audio stack), so
the choreographer, the simulator, the policy contract and the robot runner all read it.

A target row (one per policy step) is ``[paws | body]``: the four paw-height targets
(`PAW_COLUMNS`, m), then, for a whole-body dance, the four trunk targets (`BODY_COLUMNS`,
relative to standing). Slice a (T, C) array of rows with `PAWS`, `FRONT_PAWS`, `REAR_PAWS`
and `BODY` (paw slices also fit the robot's measured paw heights, in the same order);
`row_width` says how many columns a row has.
"""

from __future__ import annotations

from typing import Literal

#: Paw-height target columns, m: front left, front right, rear left, rear right.
PAW_COLUMNS: tuple[str, ...] = ("FL", "FR", "RL", "RR")
#: Trunk target columns, relative to standing: height offset (m), roll, pitch, yaw (rad).
BODY_COLUMNS: tuple[str, ...] = ("height_offset_m", "roll_rad", "pitch_rad", "yaw_rad")
N_PAWS = len(PAW_COLUMNS)
N_BODY = len(BODY_COLUMNS)
#: The paw columns of a row.
PAWS = slice(0, N_PAWS)
#: The front paws (FL, FR), the ones that dance, and the rear ones, which stay down.
FRONT_PAWS = slice(0, 2)
REAR_PAWS = slice(2, N_PAWS)
#: The trunk columns of a row.
BODY = slice(N_PAWS, N_PAWS + N_BODY)


def row_width(body: bool) -> int:
    """Columns of a target row: the paws, and the trunk's too with ``body``."""
    return N_PAWS + N_BODY if body else N_PAWS


#: Rate at which the built-in choreographer renders a human dance, Hz (the AIST++ rate).
CHOREO_FPS = 60.0

TargetMode = Literal["feasible", "paper", "minmax"]
#: Target modes (`quaddance.targets`): reachable targets, the paper's eq. 4, the released code.
MODES: tuple[str, ...] = ("feasible", "paper", "minmax")

#: Beats in a bar: 4/4 is assumed, as nearly all dance music is in four.
BEATS_PER_BAR = 4
#: The dance range, BPM: the beat level that the offline analyser and the online tracker report
#: lies in it, and the training bank's songs (`quaddance.pipeline.BANK_TEMPO_BPM`) are drawn
#: from it. A song outside it is danced at its half or double tempo.
DANCE_TEMPO_BPM = (60.0, 180.0)
