"""A stored model's arrays are checked against its centres and inputs when it is loaded."""

from __future__ import annotations

import copy

import numpy as np
import pytest

from debist.core.errors import ArtifactError
from debist.core.fileformats import H5Tree, read_h5, write_output
from debist.model.rbf import RBFModel, check_model_tree
from tests.conftest import example_rbf_model, with_physics_creep, with_slip


@pytest.fixture(scope="module")
def tree():
    """A model with backbone, prior, creep and slip terms, as stored (M = 10, two inputs)."""
    return with_slip(with_physics_creep(example_rbf_model(creep_rate=2.0))).to_tree()


def test_a_stored_model_round_trips_through_the_check(tree, tmp_path):
    write_output(H5Tree(tree), tmp_path / "model.h5")
    stored = read_h5(tmp_path / "model.h5")
    check_model_tree(stored, "model.h5")
    model = RBFModel.from_tree(stored)
    q = np.linspace(-0.01, 0.01, 7)
    np.testing.assert_array_equal(model.curves(q)["c"], RBFModel.from_tree(tree).curves(q)["c"])


@pytest.mark.parametrize(
    ("path", "value", "message"),
    [
        (("theta_c",), np.zeros(11), "model/theta_c has shape (11,), expected (10,)"),
        (("theta_d",), np.zeros((1, 10)), "model/theta_d has shape (1, 10), expected (10,)"),
        (("theta_g",), np.zeros((3, 10)), "model/theta_g has shape (3, 10), expected (2, 10)"),
        (("xi",), np.zeros((2, 5)), "model/xi has shape (2, 5), expected (M,)"),
        (("backbone", "g_0"), np.zeros(3), "model/backbone/g_0 has shape (3,), expected (2,)"),
        (("creep", "theta_creep"), np.zeros(9), "model/creep/theta_creep has shape (9,)"),
        (("slip", "theta_slip"), np.zeros(2), "model/slip/theta_slip has shape (2,)"),
        (("theta_c",), np.array(["a"] * 10), "model/theta_c: not numeric"),
        (("attrs", "n_inputs"), 0, "n_inputs: 0, expected a count >= 1"),
    ],
)
def test_an_array_of_the_wrong_shape_is_named_with_its_file(tree, path, value, message):
    bad = copy.deepcopy(tree)
    group = bad["model"]
    for key in path[:-1]:
        group = group[key]
    group[path[-1]] = value
    with pytest.raises(ArtifactError) as err:
        RBFModel.from_tree(bad, "runs/x/identify/model.h5")
    text = str(err.value)
    assert text.startswith("'runs/x/identify/model.h5': ") and message in text
    assert "\n" not in text


def test_a_missing_dataset_is_named(tree):
    bad = copy.deepcopy(tree)
    del bad["model"]["theta_g"]
    with pytest.raises(ArtifactError, match="model/theta_g: missing"):
        check_model_tree(bad, "model.h5")
