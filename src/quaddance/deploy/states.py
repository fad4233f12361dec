"""The states of a run: ``passive`` (damping) -> ``stand`` (soft start to the nominal pose)
-> ``ready`` (holds the stand; Enter or --auto-start) -> ``dance`` -> ``done`` (the policy
stands, feet down, then damping); any state but passive may fall into ``damp``. What each
state commands is `deploy.state_machine`'s; the transitions are recorded by `deploy.safety`.
"""

from __future__ import annotations

from enum import StrEnum


class DeployState(StrEnum):
    """A state of a run. Its value is the name that deploy.json's events and ``final_state``
    hold; log.npz's ``state`` column holds its `code`, and ``state_names`` the names."""

    PASSIVE = "passive"
    STAND = "stand"
    READY = "ready"
    DANCE = "dance"
    DONE = "done"
    DAMP = "damp"

    @property
    def code(self) -> int:
        """The state's number in log.npz: its place in `STATES`."""
        return STATES.index(self)


#: All states in the order of their log.npz codes.
STATES: tuple[DeployState, ...] = tuple(DeployState)
