"""The shipped search spaces compose with their entry points and name only existing keys."""

from __future__ import annotations

from pathlib import Path

import pytest
from hydra import compose, initialize_config_dir
from hydra.errors import MissingConfigException
from omegaconf import OmegaConf

from afmlearn.tune import SearchSpace

CONF = str(Path(__file__).parents[3] / "conf")
MISSING = object()


@pytest.mark.parametrize(("root", "search", "extra"), [
    ("train_qrnn", "qrnn", []),
    ("train_sindy", "identifier", []),
    ("tune", "identifier_for_recording", ["recording=rec.h5"]),
])
def test_search_space_names_existing_keys(root: str, search: str, extra: list[str]) -> None:
    OmegaConf.register_new_resolver("stem", lambda p: Path(str(p)).stem, replace=True)
    with initialize_config_dir(CONF, version_base="1.3"):
        cfg = compose(root, overrides=[f"hparams_search={search}", *extra],
                      return_hydra_config=True)
    sweeper = cfg.hydra.sweeper
    assert sweeper._target_.endswith("afmlearn_optuna_sweeper.optuna_sweeper.OptunaSweeper")
    assert cfg.hydra.mode.name == "MULTIRUN"
    space = SearchSpace.parse(OmegaConf.to_container(sweeper.params))
    assert len(space.distributions) >= 5
    for key in space.distributions:
        assert OmegaConf.select(cfg, key, default=MISSING) is not MISSING, key
    if sweeper.folds is not None:
        assert OmegaConf.select(cfg, sweeper.folds.key, default=MISSING) is not MISSING


def test_unknown_search_space_is_named() -> None:
    with initialize_config_dir(CONF, version_base="1.3"), pytest.raises(
            MissingConfigException, match="hparams_search/nonexistent"):
        compose("train_sindy", overrides=["hparams_search=nonexistent"])
