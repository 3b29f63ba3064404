"""Translator: ablations are weights at zero, skips convert units right, L_id is on the real robot only,
the replay check measures physical consistency, outputs follow the data conventions."""

import numpy as np
import pytest
import torch

from lfdt import data, layout
from lfdt.box_push_jobs.translator import box_push_kinematics
from lfdt.config import EnvConfig, RandomConfig, TranslatorConfig
from lfdt.dynamics import DynamicsModels
from lfdt.methods import translator_config
from lfdt.tasks.box_push import columns as box_columns
from lfdt.tasks.box_push.env import replay_check
from lfdt.tasks.box_push.random_motion import collect_random
from lfdt.translation import training
from lfdt.translation.apply import translator_diagnostics
from lfdt.translation.losses import Losses, normalised
from lfdt.translation.model import MeanTranslator, Translator, fit_x_normalizers
from lfdt.translation.restarts import RESTART_SEED_STRIDE, train_restarts
from lfdt.translation.training import Member, lr_factor, train_translator, train_translators
from lfdt.translation.transitions import canonical_x_columns, load_x_transitions, split_held_out

TL = box_columns.BOX_PUSH
"""The task these tests translate: the simulated box push."""


def test_methods_are_weights_at_zero():
    base = TranslatorConfig(lambda_dyn=7.0, lambda_id=3.0)
    assert translator_config("lfdt", base) == base
    assert translator_config("lfdt_no_dyn", base).lambda_dyn == 0 and \
        translator_config("lfdt_no_dyn", base).lambda_id == 3.0
    assert translator_config("lfdt_no_id", base).lambda_id == 0
    with pytest.raises(ValueError, match="unknown method 'lfdt_magic'"):
        translator_config("lfdt_magic", base)
    with pytest.raises(ValueError, match="trains no translator"):
        translator_config("bc_no_translation", base)


def test_canonical_columns_and_robot_slot():
    for p in layout.PAIRINGS:
        cols = canonical_x_columns(p, TL)
        assert cols[:8] == box_columns.arm_columns(layout.robot_arm(p)) and cols[8:18] == box_columns.arm_columns("h")
        y = box_columns.state_columns("Y")
        assert y[TL.robot_y_slice(p)] == box_columns.arm_columns(layout.robot_arm(p))


@pytest.fixture(scope="module")
def tiny(tmp_path_factory):
    root = tmp_path_factory.mktemp("tr")
    env = EnvConfig()
    paths = {}
    for d in layout.DOMAINS:
        table, _ = collect_random(d, env, RandomConfig(transitions=2_000, episodes_per_batch=20))
        paths[d] = data.write_table(table, root / f"{d}.parquet")
    dyn = DynamicsModels(19, 6, [32, 32])
    y = data.read_transitions(paths["Y"])
    dyn.y_norm.mean.copy_(torch.tensor(y[[f"state.{c}" for c in box_columns.state_columns("Y")]].mean().to_numpy()))
    dyn.y_norm.std.copy_(torch.tensor(y[[f"state.{c}" for c in box_columns.state_columns("Y")]].std().to_numpy()))
    return env, paths, dyn


def test_skips_put_hand_and_object_where_they_belong(tiny):
    env, paths, dyn = tiny
    random_x = {p: load_x_transitions(paths[p], p, kind="random", tl=TL) for p in layout.PAIRINGS}
    tr = Translator([16], TL)
    fit_x_normalizers(tr, dyn, random_x, 1e-2, object_mode="correct", hand_skip=True, tl=TL)
    torch.nn.init.zeros_(tr.G.layers[-1].weight)
    torch.nn.init.zeros_(tr.G.layers[-1].bias)  # G's own output is 0: only the skips remain
    y_cols = box_columns.state_columns("Y")
    for p in layout.PAIRINGS:
        x = random_x[p].x[:5]
        y = dyn.y_norm.inverse(tr.translate(x, p)).numpy()
        cols = canonical_x_columns(p, TL)
        missing = "r2" if layout.robot_arm(p) == "r1" else "r1"
        np.testing.assert_allclose(y[:, y_cols.index(f"{missing}.ee_x")], x[:, cols.index("h.ee_x")], atol=1e-5)
        np.testing.assert_allclose(y[:, y_cols.index("box.yaw")], x[:, cols.index("box.yaw")], atol=1e-5)
        # the real robot has no skip: its columns are G's (zero) output, i.e. the mean
        np.testing.assert_allclose(y[:, y_cols.index(f"{layout.robot_arm(p)}.q0")],
                                   float(dyn.y_norm.mean[y_cols.index(f"{layout.robot_arm(p)}.q0")]), atol=1e-5)


def test_identity_loss_pulls_the_real_robot_only(tiny):
    env, paths, dyn = tiny
    random_x = {p: load_x_transitions(paths[p], p, kind="random", tl=TL) for p in layout.PAIRINGS}
    cfg = TranslatorConfig(iterations=300, hidden=[64, 64], lambda_adv=0.0, lambda_dyn=0.0, lambda_id=1.0,
                           log_every=100, batch_size=32, kinematics="learned")
    tr, stats = train_translator(random_x, random_x, np.zeros((10, 19), np.float32), dyn, cfg, seed=0, tl=TL)
    assert [c["iteration"] for c in stats["curve"]] == [100, 200, 300]
    assert stats["curve"][-1]["loss/id"] < 0.5 * stats["curve"][0]["loss/id"]
    assert stats["curve"][-1]["loss/dyn"] > 0 and stats["curve"][-1]["loss/adv"] > 0  # measured, not trained


def test_replay_of_true_transitions_is_consistent(tiny):
    """Replaying Y's own recorded actions from Y's own start states reproduces the final box pose."""
    env, paths, _ = tiny
    df = data.read_transitions(paths["Y"])
    df = df[df.episode_index < 3]
    res = replay_check(df, env)
    assert res["replayed_demos"] == 3
    assert res["replay_box_position_error_m"] < 1e-6 and res["replay_box_yaw_error_rad"] < 1e-6
    shuffled = df.copy()
    acts = [f"action.{c}" for c in box_columns.action_columns("Y")]
    shuffled[acts] = -shuffled[acts].to_numpy()
    assert replay_check(shuffled, env)["replay_box_position_error_m"] > 1e-4


def test_forward_kinematics_makes_ends_and_velocities_consistent(tiny):
    """With Y's robot model, a translated episode's ends are the FK of its joints and its joint velocities the
    change of its joint angles per control step (zero at the start, where the arms are at rest)."""
    env, paths, dyn = tiny
    kin = box_push_kinematics(env)
    tr = Translator([16], TL, kinematics=kin)
    tr.y_mean.copy_(dyn.y_norm.mean)
    tr.y_std.copy_(dyn.y_norm.std)
    random_x = {p: load_x_transitions(paths[p], p, kind="random", tl=TL) for p in layout.PAIRINGS}
    fit_x_normalizers(tr, dyn, random_x, 1e-2, tl=TL)
    y_cols = box_columns.state_columns("Y")
    from lfdt.tasks.box_push.env import arm_specs, forward_kinematics

    for p in layout.PAIRINGS:
        t = random_x[p]
        ep = t.x[t.episode == t.episode[0]]
        y = dyn.y_norm.inverse(tr.translate(ep, p)).numpy()
        for arm in arm_specs("Y", env):
            q = y[:, [y_cols.index(f"{arm.name}.q{i}") for i in range(3)]]
            ee = y[:, [y_cols.index(f"{arm.name}.ee_x"), y_cols.index(f"{arm.name}.ee_y")]]
            dq = y[:, [y_cols.index(f"{arm.name}.dq{i}") for i in range(3)]]
            np.testing.assert_allclose(ee, forward_kinematics(arm, q), atol=1e-4)
            np.testing.assert_allclose(dq[0], 0.0, atol=1e-3)
            np.testing.assert_allclose(dq[1:], np.diff(q, axis=0) / kin.dt, atol=1e-3)


def test_held_out_split_and_checkpoint_selection(tiny):
    env, paths, dyn = tiny
    random_x = {p: load_x_transitions(paths[p], p, kind="random", tl=TL) for p in layout.PAIRINGS}
    train, held = split_held_out(random_x, 0.25, seed=0)
    for p in layout.PAIRINGS:
        assert not set(train[p].episode) & set(held[p].episode)
        assert len(train[p].x) + len(held[p].x) == len(random_x[p].x) and len(held[p].x) > 0
    assert split_held_out(random_x, 0.0, seed=0)[1] is None
    cfg = TranslatorConfig(iterations=200, hidden=[32, 32], lambda_adv=0.0, lambda_dyn=0.0, lambda_id=1.0,
                           log_every=50, select_every=50, batch_size=32, kinematics="learned")
    tr, stats = train_translator(train, random_x, np.zeros((10, 19), np.float32), dyn, cfg, seed=0,
                                 held_out=held, tl=TL)
    losses = [c["heldout/selection_loss"] for c in stats["curve"] if "heldout/selection_loss" in c]
    assert len(losses) == 4 and stats["selected_heldout_loss"] == pytest.approx(min(losses))
    assert stats["selected_iteration"] == 50 * (1 + int(np.argmin(losses)))


def test_hand_loss_pulls_the_missing_robot_to_the_hand(tiny):
    env, paths, dyn = tiny
    random_x = {p: load_x_transitions(paths[p], p, kind="random", tl=TL) for p in layout.PAIRINGS}
    cfg = TranslatorConfig(iterations=300, hidden=[64, 64], lambda_adv=0.0, lambda_dyn=0.0, lambda_id=0.0,
                           lambda_hand=1.0, log_every=100, batch_size=32, kinematics="learned")
    _, stats = train_translator(random_x, random_x, np.zeros((10, 19), np.float32), dyn, cfg, seed=0, tl=TL)
    assert stats["curve"][-1]["loss/hand"] < 0.5 * stats["curve"][0]["loss/hand"]


def test_object_weight_scales_the_object_part_of_l_dyn(tiny):
    env, paths, dyn = tiny
    random_x = {p: load_x_transitions(paths[p], p, kind="random", tl=TL) for p in layout.PAIRINGS}
    tr = Translator([16], TL)
    fit_x_normalizers(tr, dyn, random_x, 1e-2, tl=TL)
    x0, x, x2, pidx = normalised(tr, random_x)
    full = Losses(tr, dyn, TranslatorConfig(), TL)(x0, x, x2, pidx)
    none = Losses(tr, dyn, TranslatorConfig(dyn_object_weight=0.0), TL)(x0, x, x2, pidx)
    obj = full["dyn_sq"][0, :, -3:].sum(dim=1).mean() / full["dyn_sq"].shape[-1]
    assert float(none["dyn"].detach()) == pytest.approx(float((full["dyn"] - obj).detach()), rel=1e-4)


def test_forward_kinematics_needs_a_robot_model(tiny):
    env, paths, dyn = tiny
    random_x = {p: load_x_transitions(paths[p], p, kind="random", tl=TL) for p in layout.PAIRINGS}
    with pytest.raises(ValueError, match="needs the arms' kinematics"):
        train_translator(random_x, random_x, np.zeros((10, 19), np.float32), dyn,
                         TranslatorConfig(iterations=2), seed=0, tl=TL)


def test_training_and_diagnostics_raise_no_warnings(tiny):
    """A translator stage's log shows no torch warnings (a detached loss, a copied label array)."""
    import warnings

    env, paths, dyn = tiny
    random_x = {p: load_x_transitions(paths[p], p, kind="random", with_actions=True, tl=TL)
                for p in layout.PAIRINGS}
    kin = box_push_kinematics(env)
    cfg = TranslatorConfig(iterations=20, hidden=[16], log_every=10, select_every=10, batch_size=16)
    # a writable copy, as load_random_y gives the stage
    y = data.read_transitions(paths["Y"])[[f"state.{c}" for c in box_columns.state_columns("Y")]]
    y = y.to_numpy(np.float32).copy()
    with warnings.catch_warnings():
        warnings.simplefilter("error", UserWarning)
        tr, _ = train_translator(random_x, random_x, y, dyn, cfg, seed=0, kinematics=kin, tl=TL)
        with torch.no_grad():
            diag = translator_diagnostics(tr, dyn, cfg, random_x, random_x, y, kinematics=kin, tl=TL)
    assert np.isfinite(diag["labels/real_robot_rmse"])


def test_restarts_translate_with_the_mean_of_their_outputs(tiny):
    """restarts = 1 is the single translator unchanged; restarts = 2 trains a second one from seed + 1000 and
    translates with the mean of both normalised outputs; restart r logs under restart<r>/."""
    env, paths, dyn = tiny
    random_x = {p: load_x_transitions(paths[p], p, kind="random", tl=TL) for p in layout.PAIRINGS}
    y = np.zeros((10, 19), np.float32)
    cfg = TranslatorConfig(iterations=30, hidden=[16], log_every=10, select_every=10, batch_size=16,
                           kinematics="learned")
    single, _ = train_translator(random_x, random_x, y, dyn, cfg, seed=3, tl=TL)
    logged = []
    trs, stats = train_restarts(random_x, random_x, y, dyn, cfg.model_copy(update={"restarts": 2}), 3,
                                log=lambda m, i: logged.append(set(m)), tl=TL)
    other, _ = train_translator(random_x, random_x, y, dyn, cfg, seed=3 + RESTART_SEED_STRIDE, tl=TL)
    x = random_x["R1H"].x[:12]
    for a, b in zip(single.state_dict().values(), trs[0].state_dict().values()):
        assert torch.equal(a, b)
    for a, b in zip(other.state_dict().values(), trs[1].state_dict().values()):
        assert torch.equal(a, b)
    assert not torch.equal(trs[0].translate(x, "R1H"), trs[1].translate(x, "R1H"))
    torch.testing.assert_close(MeanTranslator(trs).translate(x, "R1H"),
                               (single.translate(x, "R1H") + other.translate(x, "R1H")) / 2)
    assert torch.equal(MeanTranslator(trs[:1]).translate(x, "R1H"), single.translate(x, "R1H"))
    assert len(stats) == 2 and any(all(k.startswith("restart1/") for k in m) for m in logged)
    assert any(not any(k.startswith("restart") for k in m) for m in logged)


def test_discriminator_can_see_the_robots_only(tiny):
    """disc_input 'robots': D's input is the robots' columns, so the (copied) object cannot tell it anything; 'state'
    (the paper) sees every column."""
    env, paths, dyn = tiny
    random_x = {p: load_x_transitions(paths[p], p, kind="random", tl=TL) for p in layout.PAIRINGS}
    y = np.zeros((10, 19), np.float32)
    cfg = TranslatorConfig(iterations=20, hidden=[16], log_every=10, select_every=10, batch_size=16,
                           kinematics="learned")
    n_obj = len(TL.object_cols)
    for disc_input, n_in in (("state", 19), ("robots", 19 - n_obj)):
        tr, _ = train_translator(random_x, random_x, y, dyn,
                                 cfg.model_copy(update={"disc_input": disc_input}), seed=0, tl=TL)
        assert tr.D.layers[0].weight.shape[1] == n_in
        yb = torch.randn(1, 5, 19)
        moved = yb.clone()
        moved[..., -n_obj:] += 3.0
        same = torch.equal(tr.disc(yb), tr.disc(moved))
        assert same == (disc_input == "robots")


def test_adversarial_loss_can_skip_the_demonstrations(tiny, monkeypatch):
    """adv_on 'random': D and L_adv see only the translated X random motion (the batch's second half); 'all' (the
    paper) the whole batch."""
    env, paths, dyn = tiny
    random_x = {p: load_x_transitions(paths[p], p, kind="random", tl=TL) for p in layout.PAIRINGS}
    y = np.zeros((10, 19), np.float32)
    cfg = TranslatorConfig(iterations=3, hidden=[16], log_every=10, select_every=10, batch_size=16,
                           kinematics="learned")
    orig = Translator.disc
    for adv_on, fakes in (("all", 16), ("random", 8)):
        sizes: list[int] = []

        def counting_disc(self, yb, sizes=sizes):
            sizes.append(yb.shape[1])
            return orig(self, yb)

        monkeypatch.setattr(Translator, "disc", counting_disc)
        train_translator(random_x, random_x, y, dyn, cfg.model_copy(update={"adv_on": adv_on}), seed=0, tl=TL)
        monkeypatch.setattr(Translator, "disc", orig)
        # per iteration: D on real + fakes, then L_adv on the fakes
        assert sizes[:2] == [2 * fakes, fakes]


def test_hand_offset_is_learnt_with_g_and_only_when_asked_for(tiny):
    env, paths, dyn = tiny
    random_x = {p: load_x_transitions(paths[p], p, kind="random", tl=TL) for p in layout.PAIRINGS}
    cfg = TranslatorConfig(iterations=200, hidden=[64, 64], lambda_adv=0.0, lambda_dyn=0.0, lambda_id=1.0,
                           lambda_hand=1.0, log_every=100, batch_size=32, kinematics="learned")
    plain, _ = train_translator(random_x, random_x, np.zeros((10, 19), np.float32), dyn, cfg, seed=0, tl=TL)
    assert "hand_shift" not in plain.state_dict() and plain.hand_offset_m(TL) == {}
    tr, _ = train_translator(random_x, random_x, np.zeros((10, 19), np.float32), dyn,
                             cfg.model_copy(update={"hand_offset": True}), seed=0, tl=TL)
    assert "hand_shift" in tr.state_dict() and any(p is tr.hand_shift for p in tr.generator_parameters())
    assert float(tr.hand_shift.detach().abs().max()) > 0  # trained with G
    offsets = tr.hand_offset_m(TL)
    missing_ends = [c for p in layout.PAIRINGS for c in TL.position_cols["r2" if layout.robot_arm(p) == "r1" else "r1"]]
    assert sorted(offsets) == sorted(missing_ends)
    # the loss compares with the hand plus the offset: the mean difference in a batch lowers it
    losses = Losses(tr, dyn, cfg, TL)
    batch = normalised(tr, random_x)
    with torch.no_grad():
        tr.hand_shift.zero_()
        out = losses(*batch)
        pidx = batch[3]
        hand = torch.gather(batch[1], -1, tr.hand_src[pidx]) * tr.hand_scale[pidx] + tr.hand_offset[pidx]
        diff = torch.gather(out["y_hat"], -1, tr.hand_dst[pidx]) - hand
        for i in range(len(layout.PAIRINGS)):
            tr.hand_shift[0, i] = diff[pidx == i].mean(dim=0)
        assert float(losses(*batch)["hand"]) < float(out["hand"])


def _stack_inputs(tiny, seeds):
    """What a stack of translators trains on: the arms' kinematics, X's random motion, Y's states, and one member per
    seed with its own six episodes per pairing and 30 % of them held out."""
    env, paths, dyn = tiny
    random_x = {p: load_x_transitions(paths[p], p, kind="random", tl=TL) for p in layout.PAIRINGS}
    y = data.read_transitions(paths["Y"])[[f"state.{c}" for c in box_columns.state_columns("Y")]]
    y = y.to_numpy(np.float32).copy()
    members = []
    for seed in seeds:
        eps = {p: np.unique(t.episode) for p, t in random_x.items()}
        pick = {p: t.subset(np.isin(t.episode, np.random.default_rng(seed).choice(eps[p], 6, replace=False)))
                for p, t in random_x.items()}
        train, held = split_held_out(pick, 0.3, seed)
        members.append(Member(train, seed, held))
    return box_push_kinematics(env), random_x, y, dyn, members


def test_a_seed_trains_to_the_same_bits_alone_and_in_a_stack(tiny):
    """The translators of several seeds train as one stacked model; each member's G, D, kept checkpoint and curve are
    the same bits as when that seed trains alone (its own demonstrations and held-out split, its own draws)."""
    kin, random_x, y, dyn, members = _stack_inputs(tiny, (4, 7, 11))
    cfg = TranslatorConfig(iterations=40, hidden=[32, 32], log_every=10, select_every=10, batch_size=16,
                           hand_offset=True, lambda_hand=1.0)
    stacked, st_stats = train_translators(members, random_x, y, dyn, cfg, tl=TL, kinematics=kin)
    for k, m in enumerate(members):
        alone, stats = train_translator(m.demos, random_x, y, dyn, cfg, m.seed, tl=TL, kinematics=kin,
                                        held_out=m.held_out)
        a, b = alone.state_dict(), stacked[k].state_dict()
        assert sorted(a) == sorted(b)
        assert all(torch.equal(a[key], b[key]) for key in a), f"seed {m.seed}: not the same bits in a stack"
        assert stats["curve"] == st_stats[k]["curve"]
        assert stats["selected_iteration"] == st_stats[k]["selected_iteration"]
    # and the members differ from each other (their seeds and data count)
    assert not torch.equal(stacked[0].G.layers[0].weight, stacked[1].G.layers[0].weight)


def test_a_zero_weight_sends_nothing_back_and_changes_no_bit(tiny, monkeypatch):
    """lfdt_no_dyn (lambda_dyn = 0) trains without back-propagating through F and F^-1, to the same bits as the plain
    sum of eq. 6 with its zero-weighted L_dyn."""
    kin, random_x, y, dyn, members = _stack_inputs(tiny, (4, 7))
    cfg = translator_config("lfdt_no_dyn", TranslatorConfig(iterations=30, hidden=[32, 32], log_every=10,
                                                              select_every=10, batch_size=16))
    backward_into_f = []
    plain_forward = dyn.forward_model

    def watched(y_n, a):
        out = plain_forward(y_n, a)
        if out.requires_grad:
            out.register_hook(lambda g: backward_into_f.append(1))
        return out

    monkeypatch.setattr(dyn, "forward_model", watched)
    skipped, skipped_stats = train_translators(members, random_x, y, dyn, cfg, tl=TL, kinematics=kin)
    assert not backward_into_f, "a zero-weighted L_dyn still sent its gradient back through F"
    with pytest.raises(ValueError, match="every term of the translator's loss has weight 0"):
        training.weighted_sum([(0.0, torch.ones(2)), (0, torch.ones(2))])

    def plain_sum(terms):
        total = terms[0][0] * terms[0][1]
        for w, loss in terms[1:]:
            total = total + w * loss
        return total

    monkeypatch.setattr(training, "weighted_sum", plain_sum)
    plain, plain_stats = train_translators(members, random_x, y, dyn, cfg, tl=TL, kinematics=kin)
    assert backward_into_f  # the watch works: the plain sum back-propagates 0 x L_dyn through F
    for a, b, sa, sb in zip(skipped, plain, skipped_stats, plain_stats):
        da, db = a.state_dict(), b.state_dict()
        assert all(torch.equal(da[key], db[key]) for key in da)
        assert sa["curve"] == sb["curve"] and sa["selected_iteration"] == sb["selected_iteration"]


class _Killed(Exception):
    """Stands for the stage being killed mid-training."""


def test_a_killed_training_resumes_from_its_checkpoint_to_the_same_bits(tiny, tmp_path, capsys):
    """Translator training stopped after a checkpoint and run again goes on from the checkpoint (not iteration 1),
    and ends with the same G, D, kept G, curves and selection as a run never stopped: optimiser moments, random
    draws, past fakes, partial averages and the decaying learning rate all come back. A checkpoint of another run
    (another seed) is not used, a damaged one is ignored, and a finished run found again trains no iteration."""
    kin, random_x, y, dyn, members = _stack_inputs(tiny, (4, 7))
    # log_every 3 and select_every 10: checkpoints fall between two logs (partial averages are saved)
    cfg = TranslatorConfig(iterations=40, hidden=[32, 32], log_every=3, select_every=10, batch_size=16,
                           history_size=8, lr_decay="cosine")

    def run(ckpt=None, logs=None):
        return train_translators(members, random_x, y, dyn, cfg, tl=TL, kinematics=kin, checkpoint_dir=ckpt,
                                 logs=logs)

    whole, whole_stats = run()

    def kill_at(it_stop):
        def log(point, it):
            if it >= it_stop:
                raise _Killed
        return log

    with pytest.raises(_Killed):
        run(tmp_path, [kill_at(24), None])
    assert (tmp_path / "checkpoint.pt").exists()
    seen = []
    resumed, resumed_stats = run(tmp_path, [lambda point, it: seen.append(it), None])
    assert "resuming from" in (out := capsys.readouterr().out) and "at iteration 20 of 40" in out, out
    assert seen[:len(whole_stats[0]["curve"])] == [c["iteration"] for c in whole_stats[0]["curve"]], \
        "the new run's log did not get the curve up to the checkpoint, then the rest"
    for k in range(len(members)):
        a, b = whole[k].state_dict(), resumed[k].state_dict()
        assert all(torch.equal(a[key], b[key]) for key in a), f"member {k}: not the same bits after resuming"
        assert whole_stats[k]["curve"] == resumed_stats[k]["curve"]
        assert whole_stats[k]["selected_iteration"] == resumed_stats[k]["selected_iteration"]
    # found again when finished (a failure after training): no iteration trains, the same translators
    again, _ = run(tmp_path)
    assert "at iteration 40 of 40" in capsys.readouterr().out
    assert all(torch.equal(again[0].state_dict()[key], v) for key, v in whole[0].state_dict().items())
    # another run's checkpoint (other seeds) is not resumed: it trains from iteration 1 and overwrites it
    other = [Member(members[0].demos, 99, members[0].held_out)]
    with pytest.raises(_Killed):
        train_translators(other, random_x, y, dyn, cfg, tl=TL, kinematics=kin, checkpoint_dir=tmp_path,
                          logs=[kill_at(4)])
    assert "resuming" not in capsys.readouterr().out
    # a damaged checkpoint: one line saying so, then a run from iteration 1 (still the same bits)
    (tmp_path / "checkpoint.pt").write_bytes(b"not a checkpoint")
    fresh, _ = run(tmp_path)
    assert "not a readable checkpoint" in capsys.readouterr().err
    assert all(torch.equal(fresh[0].state_dict()[key], v) for key, v in whole[0].state_dict().items())


def test_learning_rate_decays_as_asked():
    assert lr_factor("none", 500, 1000) == 1.0
    assert lr_factor("cosine", 1, 1000) == 1.0 and lr_factor("linear", 1, 1000) == 1.0
    assert lr_factor("cosine", 501, 1000) == pytest.approx(0.5)
    assert lr_factor("linear", 1000, 1000) == pytest.approx(0.001)
    assert lr_factor("cosine", 1000, 1000) < 1e-4


def test_sideways_term_ties_only_the_across_coordinate_to_the_hand(tiny):
    """lambda_side: zero when the missing robot's end lies where the hand is across the object, whatever its depth
    along it; grows with the sideways gap; and training with it alone shrinks it."""
    env, paths, dyn = tiny
    random_x = {p: load_x_transitions(paths[p], p, kind="random", tl=TL) for p in layout.PAIRINGS}
    cfg = TranslatorConfig(iterations=300, hidden=[64, 64], lambda_adv=0.0, lambda_dyn=0.0, lambda_id=0.0,
                           lambda_side=1.0, log_every=100, batch_size=32, kinematics="learned")
    tr = Translator([16], TL)
    tr.y_mean.copy_(dyn.y_norm.mean)
    tr.y_std.copy_(dyn.y_norm.std)
    fit_x_normalizers(tr, dyn, random_x, 1e-2, object_mode="copy", hand_skip=True, tl=TL)
    torch.nn.init.zeros_(tr.G.layers[-1].weight)
    torch.nn.init.zeros_(tr.G.layers[-1].bias)  # y_hat: the hand where the missing robot's end goes, the box copied
    losses = Losses(tr, dyn, cfg, TL)
    x0, x, x2, pidx = normalised(tr, {p: random_x[p] for p in layout.PAIRINGS})
    with torch.no_grad():
        y_hat = tr.generate(x, pidx)
    assert float(losses.side(y_hat, x, pidx)[0]) < 1e-10
    y_cols = box_columns.state_columns("Y")
    yaw = dyn.y_norm.inverse(y_hat[0])[:, y_cols.index("box.yaw")]
    for arm in ("r1", "r2"):
        ix, iy = y_cols.index(f"{arm}.ee_x"), y_cols.index(f"{arm}.ee_y")
        std_x, std_y = float(dyn.y_norm.std[ix]), float(dyn.y_norm.std[iy])
        # 2 cm along the object's second axis (deeper into or out of the push): no sideways gap
        along = y_hat.clone()
        along[0, :, ix] += -0.02 * torch.sin(yaw) / std_x
        along[0, :, iy] += 0.02 * torch.cos(yaw) / std_y
        assert float(losses.side(along, x, pidx)[0]) < 1e-8
        # 2 cm across it: (0.02 / std_x)^2 on the frames whose missing robot is this arm
        across = y_hat.clone()
        across[0, :, ix] += 0.02 * torch.cos(yaw) / std_x
        across[0, :, iy] += 0.02 * torch.sin(yaw) / std_y
        share = float((tr.hand_dst[pidx[0]][:, 0] == ix).float().mean())
        assert float(losses.side(across, x, pidx)[0]) == pytest.approx(share * (0.02 / std_x) ** 2, rel=1e-3)
    _, stats = train_translator(random_x, random_x, np.zeros((10, 19), np.float32), dyn, cfg, seed=0, tl=TL)
    assert stats["curve"][-1]["loss/side"] < 0.5 * stats["curve"][0]["loss/side"]


def test_across_is_the_coordinate_along_the_objects_first_axis():
    from lfdt.translation.apply import across

    pose = np.array([[0.0, 0.2, 0.0], [0.1, 0.0, np.pi / 2], [0.0, 0.0, 0.3]])
    pts = np.array([[0.03, 0.25], [0.1, 0.04], [0.05 * np.cos(0.3) - 0.02 * np.sin(0.3),
                                                 0.05 * np.sin(0.3) + 0.02 * np.cos(0.3)]])
    np.testing.assert_allclose(across(pts, pose), [0.03, 0.04, 0.05], atol=1e-12)


def test_cycle_dynamics_options_l1_dynamics_and_a_faster_discriminator(tiny):
    """dyn_norm 'l1' averages the absolute per-column error where 'l2' averages its square; d_lr_scale multiplies D's
    learning rate (Adam's first step moves each weight by about the learning rate, so D moves ~10x as far)."""
    env, paths, dyn = tiny
    random_x = {p: load_x_transitions(paths[p], p, kind="random", tl=TL) for p in layout.PAIRINGS}
    tr = Translator([16], TL)
    tr.y_mean.copy_(dyn.y_norm.mean)
    tr.y_std.copy_(dyn.y_norm.std)
    fit_x_normalizers(tr, dyn, random_x, 1e-2, tl=TL)
    batch = normalised(tr, {p: random_x[p] for p in layout.PAIRINGS})
    with torch.no_grad():
        l2 = Losses(tr, dyn, TranslatorConfig(kinematics="learned"), TL)(*batch)
        l1 = Losses(tr, dyn, TranslatorConfig(kinematics="learned", dyn_norm="l1"), TL)(*batch)
    torch.testing.assert_close(l1["dyn_sq"], l2["dyn_sq"].sqrt())
    assert float(l1["dyn"][0]) == pytest.approx(float(l1["dyn_sq"].mean()), rel=1e-5)

    def d_step(scale: float) -> float:
        cfg = TranslatorConfig(iterations=1, hidden=[16], batch_size=8, log_every=1, select_every=1,
                               kinematics="learned", d_lr_scale=scale)
        d_cols = [i for i, c in enumerate(TL.state_columns("Y")) if c not in TL.object_cols]  # D sees the robots
        init = Translator([16], TL, d_cols=d_cols, n=1, generators=[torch.Generator().manual_seed(0)]).D.state_dict()
        tr1, _ = train_translator(random_x, random_x, np.zeros((10, 19), np.float32), dyn, cfg, seed=0, tl=TL)
        return float(sum((tr1.D.state_dict()[k] - v).abs().mean() for k, v in init.items()))

    assert d_step(10.0) == pytest.approx(10 * d_step(1.0), rel=0.05)
