"""quaddance: make a Unitree Go1 quadruped dance to any piece of music."""

__version__ = "0.1.0"
