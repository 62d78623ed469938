"""``Poser.warm_up``: the live loop's first model call made before the session starts,
with nothing the next step reads changed."""

from __future__ import annotations

import numpy as np

from inference.evaluation.runner import SIX, clip_input, synthetic_motion
from inference.poser.models import resolve_model
from inference.poser.poser import Poser, _model_nets


def test_a_warmed_up_poser_answers_as_a_cold_one_and_has_built_its_network():
    model = resolve_model("diffusion")
    motion = synthetic_motion(seconds=3.0, seed=4)
    inp = clip_input(motion, SIX)
    cold = Poser(model, body=motion.body, seed=0, runtime="onnx")
    warm = Poser(model, body=motion.body, seed=0, runtime="onnx")
    _model_nets(model).clear()  # as in a new process
    warm.warm_up()
    assert any(k[0] == (2 if warm.chain_mirror else 1) for k in _model_nets(model)), "the live step's network is built"
    for t in range(len(inp.features)):
        a = cold.step(inp.features[t], inp.mask[t])
        b = warm.step(inp.features[t], inp.mask[t])
        np.testing.assert_array_equal(a.rot, b.rot)
        np.testing.assert_array_equal(a.root, b.root)
    # a fresh-noise poser's draws are not used up by it either
    fresh = [Poser(model, body=motion.body, seed=3, noise="fresh", mirror=False) for _ in range(2)]
    fresh[1].warm_up()
    for t in range(5):
        np.testing.assert_array_equal(fresh[0].step(inp.features[t], inp.mask[t]).rot,
                                      fresh[1].step(inp.features[t], inp.mask[t]).rot)
