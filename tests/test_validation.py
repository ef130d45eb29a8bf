"""A config's checks in Python (:func:`flrjax.validation.validate`): the same one-line
messages as the command line's, for a config built without it, and before anything is built."""

import pytest

from flrjax import runner, validation
from flrjax.options import ConfigError
from tests.tiny import DHRL, TINY


@pytest.mark.parametrize("flags,message", [
    (dict(polyak=1.5), "--polyak must be in [0, 1), got 1.5"),
    (dict(lr_actor=(1e-4, 1e-4)), "--lr-actor: a sweep needs distinct values"),
    (dict(lr_critic=(1e-3, 0.0)), "--lr-critic must be > 0, got 0.0"),
    (dict(steps=401), "--steps (401) must be a multiple of"),
    (dict(sweep=((("lr_critic", 1e-3),), (("lr_critic", 1e-3),))),
     "--sweep: the points must differ"),
    (dict(env="nope"), "unknown env 'nope'"),
])
def test_a_bad_config_built_in_python_names_its_flag(flags, message):
    with pytest.raises(ConfigError) as e:
        validation.validate(TINY.replace(**flags))
    assert message in str(e.value) and "\n" not in str(e.value)


def test_a_methods_own_checks_run_on_every_sweep_point():
    """A value that only one sweep point takes is checked as well as the flag's default."""
    validation.validate(DHRL)  # the shared DHRL test config is valid
    with pytest.raises(ConfigError, match="--subgoal-noise-eps must be >= 0"):
        validation.validate(DHRL.replace(sweep=((("subgoal_noise_eps", 1.0),),
                                                (("subgoal_noise_eps", -1.0),))))


def test_training_refuses_a_bad_config_before_building_anything(monkeypatch):
    def build(cfg):
        raise AssertionError("built a program for a config that fails validation")

    monkeypatch.setattr(runner, "build", build)
    with pytest.raises(ConfigError, match="--polyak"):
        runner.train(TINY.replace(polyak=1.5), progress=False)
