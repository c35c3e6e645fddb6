"""Hydra sweeper for current Optuna, shipped with afmlearn (resumable studies, heartbeats,
pruning, parallel workers). Select it with ``override /hydra/sweeper: optuna``."""
