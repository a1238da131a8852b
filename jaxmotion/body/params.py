"""The parameters every body model takes, as one pytree (MOJO's parameterisation of SMPL-X).

    params = body.zero_params()                     # BodyParams of the body's sizes
    markers = body.markers(params)                  # (M, 3): all a fitting solve evaluates
    joints = body.joints(params)                    # (J, 3)

A body model is any object with `zero_params()`, `markers(params)`, `joints(params)`,
`marker_names`, `parents`; the skeleton body (`skeleton.py`) and SMPL-X (`smplx.py`) are two.
"""

from __future__ import annotations

from typing import NamedTuple

import jax.numpy as jnp
from jaxtyping import Array, Float

from jaxmotion.body.rotation import IDENTITY_6D


class BodyParams(NamedTuple):
    """Body parameters: global translation, 6-D global orientation, shape, body pose, hand pose.

    `shape`, `pose` and `hand` have body-specific sizes (a skeleton body has no hands: size 0).
    Leading batch axes (frames, samples) are allowed on every field alike.
    """

    transl: Float[Array, "... 3"]
    orient: Float[Array, "... 6"]
    shape: Float[Array, "... s"]
    pose: Float[Array, "... p"]
    hand: Float[Array, "... h"]


def zero_params(num_shape: int, num_pose: int, num_hand: int, dtype=jnp.float32) -> BodyParams:
    """Returns parameters at the origin, identity orientation, mean shape, zero pose."""
    return BodyParams(
        transl=jnp.zeros(3, dtype),
        orient=jnp.asarray(IDENTITY_6D, dtype),
        shape=jnp.zeros(num_shape, dtype),
        pose=jnp.zeros(num_pose, dtype),
        hand=jnp.zeros(num_hand, dtype),
    )
