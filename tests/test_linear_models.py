"""Linear models in one form (femrom.study.linear_model_rows): what it refuses."""

import numpy as np
import pytest

from femrom.scene import Signal, SignalVector
from femrom.snapshots import FOMRun
from femrom.study import Cost, ModelSpec, linear_model_rows


def _run(q0):
    times = 0.01 * np.arange(5)
    cost = Cost(1.0, 1.0, 1.0, 1.0, 1.0, 1, 1.0)
    inputs = SignalVector([Signal.from_dict({"kind": "sine", "amplitude": 1.0, "frequency": 1.0})])
    return FOMRun("moved", times, np.zeros((2, 5)), None, inputs, np.asarray(q0, float), np.zeros(3), {}, cost)


def test_a_spec_names_a_known_learner():
    with pytest.raises(ValueError, match="unknown learner 'nope'; registered: .*dmdc.*okid"):
        ModelSpec("nope", "x")
    assert ModelSpec("okid", "x", {"observer_order": 4}).options == (("observer_order", 4),)


def test_runs_must_start_at_rest_where_a_model_from_rest_starts():
    # models start from z_0 = 0; a run that does not is named before anything is fitted
    with pytest.raises(ValueError, match="run 'moved' does not start at rest"):
        linear_model_rows([ModelSpec("dmdc")], [2], {"moved": _run([1.0, 0.0, 0.0])},
                          system=None, basis=None, product=None, data={})
