"""Predator-prey trial plug-in (``embodied-adhoc trials pursuit``); shares the grid-arena machinery of
:mod:`embodied_adhoc.experiments.domains.foraging`. ``--pairs`` runs the two-predator variant of Fig. 7.12."""

from __future__ import annotations

from embodied_adhoc.experiments.domains.pursuit_pairs import DOMAIN

__all__ = [
    "DOMAIN"
]  # --pairs with the decision layer's agents (Fig. 7.12): experiments/domains/pursuit_pairs.py
