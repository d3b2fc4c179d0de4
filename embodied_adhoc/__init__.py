"""embodied-adhoc: ad hoc teamwork in realistic (MuJoCo) environments.

Layers (dependencies point downward only): ``envs`` -> ``sim``/``control``/``comms``/``learning`` ->
``domains`` -> ``decision``. ``decision`` imports neither mujoco nor gymnasium.
"""

__version__ = "0.1.0"
