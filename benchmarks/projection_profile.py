"""Where the time of one projected frame goes (K = 50 vmapped LM fits on CPU): per stage, per LM step.

    flock /tmp/jaxmotion-heavy.lock python benchmarks/projection_profile.py
"""

from __future__ import annotations

import time

import jax
import jax.numpy as jnp
import numpy as np

from jaxmotion.body.fit import eq2_residuals, fit_markers
from jaxmotion.body.skeleton import toy_skeleton

K = 50


def timed(f, *a, n=5):
    jax.block_until_ready(f(*a))
    t0 = time.perf_counter()
    for _ in range(n):
        jax.block_until_ready(f(*a))
    return (time.perf_counter() - t0) / n


def main() -> None:
    body = toy_skeleton("cmu41")
    rng = np.random.default_rng(0)
    p = jax.tree.map(lambda a: jnp.broadcast_to(a, (K,) + a.shape), body.zero_params())
    true = p._replace(pose=jnp.asarray(0.3 * rng.standard_normal(p.pose.shape), jnp.float32))
    tg = jax.vmap(body.markers)(true) + 0.01 * jnp.asarray(rng.standard_normal((K, body.num_markers, 3)), jnp.float32)
    init = true._replace(pose=true.pose + 0.03)
    ones = jnp.ones(body.num_markers)
    rows = []
    fk = jax.jit(jax.vmap(body.markers))
    rows.append(("markers (forward kinematics), K=50", timed(fk, init), 1))
    jac = jax.jit(jax.vmap(jax.jacfwd(lambda q, t: eq2_residuals(body, q, t, ones))))
    rows.append(("Jacobian by jacfwd, K=50", timed(jac, init, tg), 1))
    for stages in (("global",), ("body",), ("global", "body", "hands")):
        f = jax.jit(jax.vmap(lambda t, q, s=stages: fit_markers(body, t, q, stages=s, max_steps=20, align=False)))
        steps = np.asarray(f(tg, init).num_steps).max(0).sum()  # a vmapped while loop runs to the slowest
        rows.append((f"fit stages {stages}, K=50", timed(f, tg, init, n=3), int(steps)))
    for name, s, n in rows:
        print(f"{name:55s} {1000 * s:9.2f} ms   LM steps (max over K) {n:3d}   {1000 * s / max(n, 1):7.2f} ms/step")


if __name__ == "__main__":
    main()
