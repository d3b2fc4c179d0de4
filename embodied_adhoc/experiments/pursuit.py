"""Predator-prey trial plug-in (``embodied-adhoc trials pursuit``); shares the grid-arena machinery of
:mod:`embodied_adhoc.experiments.foraging`. ``--pairs`` runs the two-predator variant of Fig. 7.12."""

from __future__ import annotations

from embodied_adhoc.experiments.foraging import GridTrialDomain

DOMAIN = GridTrialDomain("pursuit", "Predator-prey: 4 predators capture a random prey at N/S/W/E positions, "
                         "teams tau0-2 (thesis ch. 6); --pairs for Fig. 7.12", ("tau0", "tau1", "tau2", "greedy", "aware"))
