"""Metric names: namespaces, and metrics.csv's flat columns."""

import pytest

from flrjax import metric_names
from flrjax.metric_names import column, columns, is_learner, namespace, scoped

#: Every metric the built-in methods report, by the column metrics.csv had before the
#: namespaces (the header of each method's run at the commit before them).
KNOWN = {
    "low/critic_loss": "critic_loss", "low/critic_g_loss": "critic_g_loss", "low/q": "q",
    "low/actor_loss": "actor_loss", "low/reward": "reward", "low/imitation": "imitation",
    "high/critic_loss": "high_critic_loss", "high/q": "high_q",
    "high/actor_loss": "high_actor_loss", "high/landmark_loss": "landmark_loss",
    "aux/adjacency_loss": "adjacency_loss", "aux/rnd_loss": "rnd_loss",
    "stats/train_success": "train_success", "stats/physics_resets": "physics_resets",
    "stats/graph_nodes": "graph_nodes", "stats/path_length": "path_length",
    "stats/planned_steps": "planned_steps", "stats/skip_prob": "skip_prob",
    "stats/reward_gap": "reward_gap", "stats/reach_frac": "reach_frac",
    "eval/success_rate": "success_rate", "eval/falls": "falls",
    "eval/path_length": "eval_path_length", "eval/on_target_frac": "eval_on_target_frac",
    "eval/no_plan_success_rate": "no_plan_success_rate",
}


def test_known_names_keep_their_columns_and_no_two_share_one():
    assert {name: column(name) for name in KNOWN} == KNOWN
    assert len(set(KNOWN.values())) == len(KNOWN)  # a column names one metric back


def test_columns_are_in_their_alphabetical_order_and_refuse_a_shared_column():
    metrics = scoped("low", {"q": 1, "critic_loss": 2}) | {"high/q": 3, "stats/falls": 4}
    assert list(columns(metrics).items()) == [("critic_loss", 2), ("falls", 4), ("high_q", 3),
                                              ("q", 1)]
    with pytest.raises(ValueError, match="share a column"):
        columns({"stats/path_length": 1, "low/path_length": 2})


def test_a_name_needs_a_known_namespace():
    assert [namespace(n) for n in ("low/q", "aux/rnd_loss", "eval/falls")] == ["low", "aux",
                                                                                "eval"]
    for bad in ("q", "critic/q", "/q"):
        with pytest.raises(ValueError, match="namespace"):
            column(bad)


def test_learners_are_the_low_high_and_aux_namespaces():
    assert metric_names.LEARNERS == ("low", "high", "aux")
    assert [is_learner(n) for n in ("low/q", "high/q", "aux/rnd_loss", "stats/reward_gap",
                                    "eval/success_rate")] == [True, True, True, False, False]
