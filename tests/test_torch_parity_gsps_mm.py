"""GSPS and MotionMap: jaxmotion and the PyTorch twins (benchmarks/torch_ref/gsps.py, motionmap.py) compute the same functions.

Same weights (converted from jaxmotion), same inputs, same noise -> outputs, log-dets, losses,
gradients, BatchNorm running statistics and one optimiser step agree to a relative error of 1e-4
in float32 (||a - b|| / ||b||, and elementwise within 1e-4 of the array's scale), and the twins
have the same parameter counts (also at the published sizes). Skipped when PyTorch is not installed.
"""

import copy
import functools
import re
import sys
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import optax
import pytest

torch = pytest.importorskip("torch", reason="PyTorch is not installed (pip install -e '.[bench]')")
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # the repo root, for `benchmarks`

from benchmarks.torch_ref import convert  # noqa: E402
from benchmarks.torch_ref import gsps as tgsps  # noqa: E402
from benchmarks.torch_ref import motionmap as tmm  # noqa: E402
from jaxmotion.data.synthetic import SKELETON  # noqa: E402
from jaxmotion.models import gsps  # noqa: E402
from jaxmotion.models import motionmap as mm  # noqa: E402

REL = 1e-4
ZERO_GRAD = re.compile(r"gcl_(in|\d)\.gc\.bias$")  # graph-convolution biases just before a BatchNorm


def rel_close(a, b, rel=REL):
    a, b = np.asarray(a, np.float64), np.asarray(b.detach().numpy() if hasattr(b, "detach") else b, np.float64)
    assert a.shape == b.shape, (a.shape, b.shape)
    scale = np.linalg.norm(b)
    assert np.linalg.norm(a - b) <= rel * scale, np.linalg.norm(a - b) / scale
    np.testing.assert_allclose(a, b, rtol=rel, atol=rel * np.max(np.abs(b)))


def grads_close(torch_module, jax_grads_module) -> float:
    """Checks every `.grad` of `torch_module` against the same parameter of `jax_grads_module` (jax gradients loaded by
    convert), each tensor to 1e-4 of its own norm; returns the largest relative difference.

    A graph convolution's bias just before a BatchNorm (`...gcl_*.gc.bias`) has a zero gradient in exact
    arithmetic (the normalisation removes any shift); in float32 both frameworks give rounding noise
    there, so for those the check is that both are below 1e-2 of the whole gradient's norm.
    """
    named, ref = list(torch_module.named_parameters()), list(jax_grads_module.parameters())
    assert len(named) == len(ref) > 0
    total = np.sqrt(sum(float(torch.sum(r.detach() ** 2)) for r in ref))
    worst = 0.0
    for (name, p), r in zip(named, ref):
        a, b = p.grad.numpy().astype(np.float64), r.detach().numpy().astype(np.float64)
        if ZERO_GRAD.search(name):
            assert max(np.linalg.norm(a), np.linalg.norm(b)) <= 1e-2 * total, name
            continue
        err = np.linalg.norm(a - b) / np.linalg.norm(b)
        assert err <= REL, (name, err)
        worst = max(worst, err)
    return worst


def n_params(tree) -> int:
    return sum(int(np.size(v)) for v in jax.tree.leaves(tree))


def n_torch(module, buffers: bool = False) -> int:
    n = sum(p.numel() for p in module.parameters())
    return n + (sum(b.numel() for k, b in module.named_buffers() if "running" in k) if buffers else 0)


def tt(a):
    return torch.tensor(np.asarray(a))


# ---------------------------------------------------------------------------------------------
# GSPS: the skeleton of the synthetic data (16 joints below the root, named like Human3.6M's).

PARENTS = SKELETON.parents
ROLES = gsps.angle_roles(SKELETON.names, PARENTS)
PARTS = gsps.body_parts(SKELETON.names, PARENTS, "lower_upper")
D, J = 48, 16
T_HIS, T_PRED, B, NZ, N_PRE, HID, NK1, NK2, M = 4, 6, 2, 4, 3, 16, 3, 2, 3
WEIGHTS = dict(lambda_his=100.0, lambda_limb=500.0, lambda_div_first=8.0, lambda_div_rest=25.0, alpha=100.0, beta=300.0,
               lambda_recon=2.0, lambda_recon_mm=1.0, lambda_prior=0.01, prior_stride=3, lambda_angle=100.0)


def poses(seed, *lead) -> np.ndarray:
    """Returns frames `(*lead, 48)` of a random skeleton: each joint its parent plus a random bone, jittered per frame."""
    rng = np.random.default_rng(seed)
    bones = rng.normal(0, 0.2, (len(PARENTS), 3)) + rng.normal(0, 0.05, lead + (len(PARENTS), 3))
    pos = [np.zeros(lead + (3,))]
    for j in range(1, len(PARENTS)):
        pos.append(pos[PARENTS[j]] + bones[..., j, :])
    return np.stack(pos[1:], axis=-2).reshape(lead + (D,)).astype(np.float32)


def bounds() -> np.ndarray:
    """Returns cosine bounds most poses violate somewhere; two families open (outside +-0.98) on one side."""
    rng = np.random.default_rng(3)
    b = np.stack([rng.uniform(-0.6, -0.1, 17), rng.uniform(0.1, 0.6, 17)], -1)
    b[2, 0], b[9, 1] = -1.0, 0.99
    return b.astype(np.float32)


def test_torch_twin_knows_jaxmotion_angle_names():
    assert tgsps.ANGLE_NAMES == gsps.ANGLE_NAMES


def test_angle_cosines_violations_and_loss_match():
    f = jnp.asarray(poses(0, 50))
    rel_close(gsps.angle_cosines(f, ROLES), tgsps.angle_cosines(tt(f), ROLES))
    cos = np.asarray(gsps.angle_cosines(f, ROLES))
    rel_close(gsps.angle_violations(jnp.asarray(cos), jnp.asarray(bounds())), tgsps.angle_violations(tt(cos), tt(bounds())))
    jl = gsps.angle_loss(jnp.asarray(cos), jnp.asarray(bounds()))
    assert float(jl) > 0
    rel_close(jl, tgsps.angle_loss(tt(cos), tt(bounds())))
    rel_close(gsps.limb_directions(f, PARENTS), tgsps.limb_directions(tt(f), PARENTS))


@pytest.fixture(scope="module")
def prior_pair():
    jp = gsps.PosePrior(dim=D, n_layers=3)
    pp = jax.jit(jp.init)(jax.random.key(0), jnp.zeros((1, D)))
    tp = convert.gsps_prior(tgsps.PosePrior(D, 3), pp)
    return jp, pp, tp


def test_gsps_prior_parameter_counts_match(prior_pair):
    _, pp, tp = prior_pair
    assert n_params(pp) == n_torch(tp) == 3 * (2 * D * D + D) + 2


@pytest.mark.slow  # float64 autograd Jacobian and three jitted applies
def test_gsps_prior_forward_logdet_inverse_and_loss_match(prior_pair):
    jp, pp, tp = prior_pair
    frames = jnp.asarray(poses(1, 64))
    d = gsps.limb_directions(frames, PARENTS)
    jz, jld = jp.apply(pp, d)
    with torch.no_grad():
        tz, tld = tp(tt(d))
        rel_close(jz, tz)
        rel_close(jld, tld)
        # Both PReLUs see negative inputs, so the log-det is not the LinQR layers' constant alone.
        assert np.ptp(np.asarray(jld)) > 0.1
        rel_close(jp.apply(pp, jz, method=gsps.PosePrior.inverse), tp.inverse(tz))
        rel_close(tp.inverse(tz), np.asarray(d))  # the twin's own inverse inverts
        rel_close(jp.apply(pp, d, method=gsps.PosePrior.log_prob), tp.log_prob(tt(d)))
    jl, jmet = gsps.prior_loss(jp, pp, frames, parents=PARENTS)
    tl, tmet = tgsps.prior_loss(tp, tt(frames), parents=PARENTS)
    rel_close(jl, tl)
    for k in jmet:
        rel_close(jmet[k], tmet[k])
    # The twin's log-det is log |det| of its Jacobian (autograd), as the flow's equations say.
    one = tt(d[0]).double()
    tp64 = copy.deepcopy(tp).double()
    jac = torch.autograd.functional.jacobian(lambda v: tp64(v)[0], one)
    np.testing.assert_allclose(float(torch.linalg.slogdet(jac)[1]), float(tp64(one)[1].detach()), rtol=1e-10, atol=1e-9)


def test_gsps_prior_loss_gradients_match(prior_pair):
    jp, pp, tp = prior_pair
    frames = jnp.asarray(poses(2, 64))
    g = jax.jit(jax.grad(lambda p: gsps.prior_loss(jp, p, frames, parents=PARENTS)[0]))(pp)
    tp.zero_grad()
    tgsps.prior_loss(tp, tt(frames), parents=PARENTS)[0].backward()
    grads_close(tp, convert.gsps_prior(tgsps.PosePrior(D, 3), g))


@pytest.fixture(scope="module")
def gen_pair():
    jg = gsps.GSPSGenerator(parts=PARTS, hidden=HID, num_stage=1)
    v = jax.jit(functools.partial(jg.init, train=False))(
        jax.random.key(4), jnp.zeros((2, J, 3 * N_PRE)), jnp.zeros((2, len(PARTS), NZ)))
    # Non-trivial running statistics, so evaluation mode and the running-average update are really tested.
    rng = np.random.default_rng(5)
    v = {"params": v["params"], "batch_stats": jax.tree_util.tree_map_with_path(
        lambda path, a: rng.uniform(0.5, 2.0, a.shape).astype(np.float32) if path[-1].key == "var"
        else rng.normal(0, 0.3, a.shape).astype(np.float32), v["batch_stats"])}
    make = lambda: tgsps.GSPSGenerator(J, PARTS, n_pre=N_PRE, nz=NZ, hidden=HID, num_stage=1)  # noqa: E731
    return jg, v, make


@pytest.mark.slow  # compiles the generator's init
def test_gsps_generator_parameter_counts_match(gen_pair):
    jg, v, make = gen_pair
    assert n_params(v) == n_torch(make(), buffers=True)
    c = gsps.GSPSConfig()  # the release's Human3.6M generator: 16 nodes, 10 coefficients, 256 hidden, 4 stages
    big = gsps.GSPSGenerator(parts=PARTS, hidden=c.hidden, num_stage=c.num_stage)
    shapes = jax.eval_shape(lambda: big.init(jax.random.key(0), jnp.zeros((2, J, 3 * c.n_pre)),
                                             jnp.zeros((2, 2, c.nz)), train=False))
    assert n_params(shapes["params"]) == n_torch(tgsps.GSPSGenerator(J, PARTS))


def _gsps_batch(seed):
    w = poses(seed, B, T_HIS + T_PRED)
    fut = poses(seed + 1, B, M, T_PRED)
    mask = np.array([[1, 1, 0], [1, 0, 0]], np.float32)
    return {"window": w, "mm": fut * mask[..., None, None], "mm_mask": mask}


def _gsps_loss_kw():
    return dict(t_his=T_HIS, parents=PARENTS, parts=PARTS, roles=ROLES, nk1=NK1, nk2=NK2, **WEIGHTS)


@pytest.mark.slow  # compiles the generator loss and its gradient
def test_gsps_generator_training_step_matches(gen_pair, prior_pair):
    """Train-mode outputs, every loss term, gradients, BatchNorm running statistics and a clipped Adam step."""
    jg, v, make = gen_pair
    jp, pp, tp = prior_pair
    batch = _gsps_batch(10)
    key = jax.random.key(11)
    # The draws generator_loss makes from `key`: the nk1 x nk2 noise grid, the prior's frame phase.
    k_noise, k_phase = jax.random.split(key)
    z = np.asarray(gsps.training_noise(k_noise, B, len(PARTS), NK1, NK2, NZ))
    phase = int(jax.random.randint(k_phase, (), 0, WEIGHTS["prior_stride"]))
    kw = _gsps_loss_kw()
    loss_fn = functools.partial(gsps.generator_loss, jg, prior=jp, n_pre=N_PRE, nz=NZ, **kw)

    def jloss(variables, frozen, b, k):
        return loss_fn(variables, prior_params=frozen["prior"], angle_bounds=frozen["bounds"], batch=b, key=k)

    frozen = {"prior": pp, "bounds": jnp.asarray(bounds())}
    (jl, (jmet, jstats)), jgrad = jax.jit(jax.value_and_grad(jloss, has_aux=True))(v, frozen, batch, key)

    tg = convert.gsps_generator(make(), v).train()
    tp.requires_grad_(False)
    tb = {k: tt(a) for k, a in batch.items()}
    tl, tmet = tgsps.generator_loss(tg, tp, tb, tt(z), phase, angle_bounds=tt(bounds()), **kw)
    tg.zero_grad()
    tl.backward()
    tp.requires_grad_(True)
    rel_close(jl, tl)
    assert set(jmet) == set(tmet)
    for name in jmet:
        rel_close(jmet[name], tmet[name])
    assert 0 < float(jmet["angle"]) and 0 < float(jmet["recon_mm"]) and 0 < float(jmet["div_first"]) < 1
    grads_close(tg, convert.gsps_generator(make(), {"params": jgrad["params"]}))
    # The running statistics after the step: jaxmotion's (unbiased variance) are nn.BatchNorm1d's.
    after = convert.gsps_generator(make(), {"params": v["params"], "batch_stats": jstats})
    bufs = dict(after.named_buffers())
    named = [(k, b) for k, b in tg.named_buffers() if "running" in k]
    assert len(named) == 2 * 2 * (1 + 2)  # 2 parts x (mean, var) x 3 GCL blocks
    for name, buf in named:
        rel_close(bufs[name], buf)
    # One optimiser step of the release (gradient clipping at norm 100, then Adam 1e-3) lands on the same weights.
    tx = optax.chain(optax.clip_by_global_norm(100.0), optax.adam(1e-3))
    upd, _ = tx.update(jgrad["params"], tx.init(v["params"]), v["params"])
    new = optax.apply_updates(v["params"], upd)
    opt = torch.optim.Adam(tg.parameters(), 1e-3)
    torch.nn.utils.clip_grad_norm_(list(tg.parameters()), 100.0)
    opt.step()
    stepped = convert.gsps_generator(make(), {"params": new})
    for (name, a), b in zip(tg.named_parameters(), stepped.parameters()):
        if not ZERO_GRAD.search(name):  # Adam's first step is lr * sign(g): rounding noise decides it there
            rel_close(b.detach().numpy(), a, rel=REL)


@pytest.mark.slow  # runs the generator twice in evaluation mode
def test_gsps_sampling_in_eval_mode_matches(gen_pair):
    jg, v, make = gen_pair
    tg = convert.gsps_generator(make(), v).eval()
    x = poses(20, B, T_HIS)
    k = 5
    z = np.asarray(gsps.sample_noise(jax.random.key(21), B, k, len(PARTS), NZ))
    jseq, _ = gsps.generate(jg, v, jnp.asarray(x), jnp.asarray(z), t_pred=T_PRED, n_pre=N_PRE, train=False)
    with torch.no_grad():
        tseq = tgsps.generate(tg, tt(x), tt(z), t_pred=T_PRED)
        rel_close(jseq, tseq)
        rel_close(jseq[:, :, T_HIS:], tgsps.sample_gsps(tg, tt(x), tt(z), t_pred=T_PRED))
    # Part control: one lower-body noise across the K samples -> one lower-body motion in both frameworks.
    zc = np.asarray(gsps.part_control_noise(jax.random.key(22), B, k, len(PARTS), NZ, fixed=(0,)))
    with torch.no_grad():
        tc = tgsps.generate(tg, tt(x), tt(zc), t_pred=T_PRED)
    jc, _ = gsps.generate(jg, v, jnp.asarray(x), jnp.asarray(zc), t_pred=T_PRED, n_pre=N_PRE, train=False)
    rel_close(jc, tc)
    lower = gsps.part_coords(PARTS)[0]
    assert float(torch.max(torch.std(tc[..., lower], dim=1))) < 1e-5


@pytest.mark.slow  # builds the generator
def test_conversion_rejects_mismatched_gsps_sizes(gen_pair, prior_pair):
    _, v, _ = gen_pair
    with pytest.raises(ValueError, match="part_0"):
        convert.gsps_generator(tgsps.GSPSGenerator(J, PARTS, n_pre=N_PRE + 1, nz=NZ, hidden=HID, num_stage=1), v)
    with pytest.raises(ValueError, match="LinQR"):
        convert.gsps_prior(tgsps.PosePrior(D, 2), prior_pair[1])


# ---------------------------------------------------------------------------------------------
# MotionMap

MD, MT_HIS, MT_PRED, MB, SIZE = 6, 4, 5, 3, 8
MCFG = mm.MotionMapConfig(nh_rnn=12, nh_fuse=16, nh_uncertainty=10, n_uncertainty_layers=2, hm_size=SIZE,
                          hm_channels=4, hm_convs=2)


def mdata(seed, *shape):
    return np.random.default_rng(seed).normal(size=shape).astype(np.float32)


@pytest.fixture(scope="module")
def ae_pair():
    ja = mm.ae_model(MCFG, MD, MT_HIS, MT_PRED)
    p = jax.jit(ja.init)(jax.random.key(0), jnp.zeros((1, MT_HIS, MD)), jnp.zeros((1, MT_PRED, MD)))
    make = lambda: tmm.MotionMapAE(MD, MT_HIS, MT_PRED, MCFG.nh_rnn, MCFG.nh_fuse, MCFG.nh_uncertainty,  # noqa: E731
                                   MCFG.n_uncertainty_layers)
    return ja, p, make


@pytest.fixture(scope="module")
def hm_pair():
    jh = mm.heatmap_model(MCFG)
    p = jax.jit(jh.init)(jax.random.key(1), jnp.zeros((1, MT_HIS, MD)))
    make = lambda: tmm.HeatmapNet(MD, SIZE, MCFG.nh_rnn, MCFG.hm_channels, MCFG.hm_convs, MCFG.descriptor_frames)  # noqa: E731
    return jh, p, make


@pytest.mark.slow  # compiles both networks' init
def test_motionmap_parameter_counts_match(ae_pair, hm_pair):
    _, p, make = ae_pair
    assert n_params(p) == n_torch(make())
    _, hp, hmake = hm_pair
    assert n_params(hp) == n_torch(hmake())
    c = mm.MotionMapConfig(hm_size=128)  # the release's sizes (its 128 x 128 map) on Bandai-Namco-2's D = 60
    big = mm.ae_model(c, 60, 15, 60)
    shapes = jax.eval_shape(lambda: big.init(jax.random.key(0), jnp.zeros((1, 15, 60)), jnp.zeros((1, 60, 60))))
    assert n_params(shapes) == n_torch(tmm.MotionMapAE(60, 15, 60))
    hshapes = jax.eval_shape(lambda: mm.heatmap_model(c).init(jax.random.key(0), jnp.zeros((1, 15, 60))))
    assert n_params(hshapes) == n_torch(tmm.HeatmapNet(60, 128))


@pytest.mark.slow  # compiles the autoencoder loss and gradient
def test_motionmap_autoencoder_outputs_losses_and_gradients_match(ae_pair):
    ja, p, make = ae_pair
    ta = convert.motionmap_ae(make(), p)
    batch = {"x": jnp.asarray(mdata(0, MB, MT_HIS, MD)), "y": jnp.asarray(mdata(1, MB, MT_PRED, MD))}
    jf, jls = ja.apply(p, batch["x"], batch["y"])
    with torch.no_grad():
        tf, tls = ta(tt(batch["x"]), tt(batch["y"]))
    rel_close(jf, tf)
    rel_close(jls, tls)
    scale = MCFG.loss_scale
    (jl, jmet), g = jax.jit(jax.value_and_grad(lambda q: mm.ae_loss(ja, q, batch, scale=scale), has_aux=True))(p)
    ta.zero_grad()
    tl, tmet = tmm.ae_loss(ta, {k: tt(a) for k, a in batch.items()}, scale=scale)
    tl.backward()
    rel_close(jl, tl)
    for name in jmet:
        rel_close(jmet[name], tmet[name])
    grads_close(ta, convert.motionmap_ae(make(), g))
    # The uncertainty head learns from the NLL only; the rest from the reconstruction only (stopped gradients).
    assert float(torch.linalg.norm(ta.uncertainty_out.weight.grad)) > 0
    # Stage 4: decoding codebook codes.
    table = mdata(2, SIZE * SIZE, MCFG.nh_rnn)
    fb = dict(batch, cell=jnp.array([3, 17, 63], jnp.int32))
    jl, _ = mm.finetune_loss(ja, p, jnp.asarray(table), fb, scale=scale)
    with torch.no_grad():
        tl, _ = tmm.finetune_loss(ta, tt(table), {k: tt(a) for k, a in fb.items()}, scale=scale)
    rel_close(jl, tl)


@pytest.mark.slow  # compiles the heatmap loss and gradient
def test_motionmap_heatmap_forward_loss_and_gradients_match(hm_pair):
    jh, p, make = hm_pair
    th = convert.motionmap_heatmap(make(), p)
    x = jnp.asarray(mdata(3, MB, MT_HIS, MD))
    with torch.no_grad():
        rel_close(jh.apply(p, x), th(tt(x)))
    rng = np.random.default_rng(4)
    cells = jnp.asarray(rng.integers(0, SIZE, (20, 2)).astype(np.int32))
    batch = {"x": x, "members": jnp.asarray(rng.integers(0, 20, (MB, 4)).astype(np.int32)),
             "mask": jnp.array([[1, 1, 1, 0], [1, 0, 0, 0], [1, 1, 1, 1]], bool)}
    kw = dict(size=SIZE, sigma=MCFG.hm_sigma, pos_weight=MCFG.pos_weight)
    rel_close(jax.vmap(lambda ix, mk: mm.gaussian_heatmap(cells[ix].astype(jnp.float32), mk, SIZE, MCFG.hm_sigma))(
        batch["members"], batch["mask"]), tmm.gaussian_heatmap(tt(cells)[tt(batch["members"])].float(), tt(batch["mask"]),
                                                             SIZE, MCFG.hm_sigma))
    (jl, jmet), g = jax.jit(jax.value_and_grad(lambda q: mm.heatmap_loss(jh, q, cells, batch, **kw), has_aux=True))(p)
    th.zero_grad()
    tl, tmet = tmm.heatmap_loss(th, tt(cells), {k: tt(a) for k, a in batch.items()}, **kw)
    tl.backward()
    rel_close(jl, tl)
    for name in jmet:
        rel_close(jmet[name], tmet[name])
    grads_close(th, convert.motionmap_heatmap(make(), g))


@pytest.mark.slow  # builds both networks
def test_conversion_rejects_mismatched_motionmap_sizes(ae_pair, hm_pair):
    with pytest.raises(ValueError, match="enc_x"):
        convert.motionmap_ae(tmm.MotionMapAE(MD + 3, MT_HIS, MT_PRED, MCFG.nh_rnn, MCFG.nh_fuse), ae_pair[1])
    with pytest.raises(ValueError, match="convolutions"):
        convert.motionmap_heatmap(tmm.HeatmapNet(MD, SIZE, MCFG.nh_rnn, MCFG.hm_channels, 3), hm_pair[1])
