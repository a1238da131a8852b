"""jaxmotion.train.compile_time: the seconds jax spends compiling inside a block, from its own compile events."""

import jax
import jax.numpy as jnp

from jaxmotion.train.compile_time import CompileTimer, union_seconds


def test_union_counts_overlapping_spans_once():
    assert union_seconds([(0.0, 2.0), (1.0, 3.0), (5.0, 6.0), (5.5, 5.7)]) == 4.0
    assert union_seconds([]) == 0.0


def test_a_first_call_compiles_and_a_second_does_not():
    f = jax.jit(lambda x: jnp.tanh(x) @ x.T)
    x = jnp.ones((8, 8))
    with CompileTimer() as first:
        f(x).block_until_ready()
    with CompileTimer() as second:
        f(x).block_until_ready()
    assert first.seconds > 0 and second.seconds == 0
