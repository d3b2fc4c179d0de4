"""Gymnasium envs (abstract and embodied). Importing this package registers every id in ``registry.ENV_SPECS``."""

from embodied_adhoc.envs.registry import ENV_SPECS, register_all

register_all()

__all__ = ["ENV_SPECS", "register_all"]
