"""The ball's form as a device candidate: a ball with lobes about its stem, read by the
R-test's sensors where they touch it, simulated here from the ball's surface itself (its
support function found by search, not compgen's first-order columns)."""

import html

import numpy as np
import pytest
from conftest import TABLE4, UM

from compgen.data.rtest import MOUNTED_AGAIN, RTestData
from compgen.data.simulate import simulate
from compgen.model.frames import sensors_on_ball
from compgen.model.paths import generate
from compgen.planning.advice import Advisor
from compgen.statistics.device import form_columns
from compgen.statistics.diagnose import diagnose
from compgen.statistics.gate import gate_reasons
from compgen.statistics.identify import identify

NOISE_UM = 0.5
RADIUS_MM = 12.7          # the ball's: the form's first order does not depend on it
SEARCH = np.linspace(-4e-4, 4e-4, 41)      # rad about each sensor's direction


def _support(u: np.ndarray, size_mm: float, k: int, phase: float) -> np.ndarray:
    """h(u) = max over the surface of p·u, for the ball of radius RADIUS_MM + size·sinᵏθ·cos k(φ − phase)
    (ball frame), found on a grid of directions about each u (m, 3)."""
    t1 = np.cross(u, [0.0, 0.0, 1.0])
    t1[np.linalg.norm(t1, axis=1) < 1e-9] = [1.0, 0.0, 0.0]
    t1 /= np.linalg.norm(t1, axis=1)[:, None]
    t2 = np.cross(u, t1)
    a, b = np.meshgrid(SEARCH, SEARCH)
    v = u[:, None, :] + a.ravel()[None, :, None] * t1[:, None, :] + b.ravel()[None, :, None] * t2[:, None, :]
    v /= np.linalg.norm(v, axis=2)[:, :, None]
    lobes = ((v[..., 0] + 1j * v[..., 1]) * np.exp(-1j * phase)) ** k
    r = RADIUS_MM + size_mm * lobes.real
    return np.max(r * np.einsum("mgi,mi->mg", v, u), axis=1)


def _form_readings(machine, poses, size_um: float, k: int, phase: float, turn: float) -> np.ndarray:
    """Nest minus ball (n, 3) mm that the form alone makes: sensor s touches the ball on its
    side along s, the ball turned ``turn`` rad on its stem."""
    sensors, on_table = sensors_on_ball(machine, poses.q)
    out = np.zeros((len(poses), 3))
    for s in range(3):
        e, u = sensors[:, :, s], on_table[:, :, s]
        c, w = np.cos(-turn), np.sin(-turn)
        u = np.stack([c * u[:, 0] - w * u[:, 1], w * u[:, 0] + c * u[:, 1], u[:, 2]], axis=1)   # the ball's
        out -= e * (_support(u, size_um * 1e-3, k, phase) - RADIUS_MM)[:, None]
    return out


def _session(machine, poses, truth, form, turn, seed, source, said=""):
    """An R-test file of the machine ``truth`` read on a ball with ``form`` (size µm, k, phase)."""
    d = simulate(machine, truth, poses)
    rng = np.random.default_rng(seed)
    dev = (d.deviation + _form_readings(machine, poses, *form, turn)
           + rng.normal(0, NOISE_UM * 1e-3, (len(poses), 3)))
    return RTestData(d.poses, dev, source, "", tuple(range(2, len(poses) + 2)), said=said,
                     turned=float(np.degrees(turn)) if said else 0.0)


def test_the_forms_columns_are_what_the_ball_itself_reads(seed_machine, head_machine):
    """compgen's first-order columns of each lobe order against the support function of the
    ball's surface searched directly, on the trunnion and on a head (its sensors turn with
    the tool), the ball turned 40° on its stem: within 0.2 % of the form's size."""
    for machine in (seed_machine, head_machine):
        poses = generate(machine, ["K4", "K1", "K2"])
        turned = type(poses)(**{**{f: getattr(poses, f) for f in ("q", "ball", "t", "path", "side", "nest",
                                                                      "setup")}, "turn": np.full(len(poses),
                                                                                                np.radians(40))})
        rtest = np.ones(len(poses), bool)
        for k in (2, 3, 4):
            cols = form_columns(machine, turned, rtest)[f"ball_lobes{k}"]
            for phase in (0.0, 0.7):
                want = _form_readings(machine, poses, 1.0, k, phase, np.radians(40))
                got = (cols @ (1e-3 * np.array([np.cos(k * phase), np.sin(k * phase)]))).reshape(-1, 3)
                assert np.abs(got - want).max() < 2e-6, (machine.name, k, phase, np.abs(got - want).max())
                assert np.abs(want).max() > 0.5e-3, (machine.name, k)     # the form is seen


@pytest.mark.parametrize("seed", [3, 4])
def test_a_ball_with_three_lobes_is_not_named_a_machine_effect_until_the_ball_is_turned(seed_machine, seed):
    """A ball 0.8 µm out of round in three lobes about its stem reads on K4, K1, K2 as C's
    radial motion against it at 3/rev does, to 0.04 µm: neither is named found, the two are
    said tied. Measured again with the ball turned 60° on its stem (and so mounted again),
    the form is blamed, its size within 3σ of 0.8 µm, and no machine effect is found."""
    poses = generate(seed_machine, ["K4", "K1", "K2"])
    form = (0.8, 3, 0.4)
    data = [_session(seed_machine, poses, TABLE4, form, 0.0, seed, "a.csv")]
    d = diagnose(seed_machine, data, identify(seed_machine, data), noise_um=NOISE_UM, advisor=Advisor)
    assert d.verdict == "rivals" and d.form_rival == "ball_lobes3" and d.found is None, \
        (d.verdict, d.form_rival, d.found, [c.effect for c in d.significant[:3]])
    fit = identify(seed_machine, data)
    assert any("the ball's form (ball_lobes3)" in r and "turn the ball" in r
               for r in gate_reasons(data, fit, d)), gate_reasons(data, fit, d)
    k4 = generate(seed_machine, ["K4"]).starting_at(float(poses.t[-1]) + 60.0)
    moved = {**TABLE4, "XOW": 4 * UM, "YOW": -3 * UM, "ZOW": 2 * UM}
    data.append(_session(seed_machine, k4, moved, form, np.radians(60.0), seed + 10, "b.csv", MOUNTED_AGAIN))
    d = diagnose(seed_machine, data, identify(seed_machine, data), noise_um=NOISE_UM, advisor=Advisor)
    assert d.verdict == "device" and d.device_blamed == "ball_lobes3" and d.found is None, \
        (d.verdict, d.device_blamed, d.form_rival, d.found)
    fit = identify(seed_machine, data)
    assert any(r.startswith("the ball's form explains the misfit") for r in gate_reasons(data, fit, d))
    assert abs(d.blamed.value - 0.8) < 3 * d.blamed.std < 0.3, d.blamed


@pytest.mark.parametrize("seed", [3, 4])
def test_a_radial_3_rev_of_c_is_found_once_the_ball_turned_shows_it_is_no_form(seed_machine, seed):
    """The other way round: C's radial motion against it at 3/rev, 2 µm, on a round ball. The
    same K4 measured with the ball turned 60° reads it the same way: the machine's effect is
    found and the ball's form is neither blamed nor tied with it."""
    poses = generate(seed_machine, ["K4", "K1", "K2"])
    truth = {**TABLE4, "EXC+EYC:h-3c": 2 * UM}
    data = [_session(seed_machine, poses, truth, (0.0, 3, 0.0), 0.0, seed, "a.csv")]
    k4 = generate(seed_machine, ["K4"]).starting_at(float(poses.t[-1]) + 60.0)
    moved = {**truth, "XOW": 4 * UM, "YOW": -3 * UM, "ZOW": 2 * UM}
    data.append(_session(seed_machine, k4, moved, (0.0, 3, 0.0), np.radians(60.0), seed + 10, "b.csv",
                         MOUNTED_AGAIN))
    d = diagnose(seed_machine, data, identify(seed_machine, data), noise_um=NOISE_UM, advisor=Advisor)
    assert d.found == "EXC+EYC:h-3" and d.form_rival is None and d.device_blamed is None, \
        (d.verdict, d.found, d.form_rival, d.device_blamed, d.rivals)


def test_the_printed_turn_pastes_and_ends_with_the_ball_blamed(seed_machine, tmp_path):
    """As a user follows it: diagnose names the tie and prints the program for the same path
    with the ball turned and the fit that says the turn; each line pasted into bash runs (the
    readings saved as it says), and the diagnosis after blames the ball's form."""
    from conftest import SEED_MACHINE, pasted

    from compgen.data.rtest import format_rtest
    poses = generate(seed_machine, ["K4", "K1", "K2"])
    form = (0.8, 3, 0.4)
    first = _session(seed_machine, poses, TABLE4, form, 0.0, 3, "a.csv")
    (tmp_path / "a.csv").write_text(format_rtest(seed_machine, first))
    done = pasted(f"compgen-cli fit --machine {SEED_MACHINE} a.csv -o fit.json && "
                  "compgen-cli diagnose --from fit.json", tmp_path)
    assert done.returncode == 0, done.stderr
    first = next(line for line in done.stdout.splitlines() if line.startswith("VERDICT"))
    said = "vs the ball's form (ball_lobes3); turn the ball 60° on its stem and measure K2 again"
    assert said in first, first
    report = pasted("compgen-cli report --from fit.json -o r.html", tmp_path)
    assert report.returncode == 0, report.stderr
    page = html.unescape((tmp_path / "r.html").read_text())
    assert "the ball's form (ball_lobes3); turn the ball 60° on its stem" in page
    assert "they predict the same readings everywhere" not in page
    printed = [line.strip() for line in done.stdout.splitlines() if line.strip().startswith("compgen-cli ")]
    program = next(line for line in printed if " measure-program " in line and "_TURNED" in line)
    refit = next(line for line in printed if "--ball-turned" in line)
    assert pasted(program, tmp_path).returncode == 0 and (tmp_path / "K2_TURNED.H").exists()
    k2 = generate(seed_machine, ["K2"]).starting_at(float(poses.t[-1]) + 60.0)
    moved = {**TABLE4, "XOW": 4 * UM, "YOW": -3 * UM, "ZOW": 2 * UM}
    (tmp_path / "K2_TURNED.csv").write_text(format_rtest(seed_machine, _session(
        seed_machine, k2, moved, form, np.radians(60.0), 13, "K2_TURNED.csv")))
    done = pasted(refit, tmp_path)
    assert done.returncode == 0, done.stderr
    after = refit.split(" -o ")[-1]
    done = pasted(f"compgen-cli diagnose --from {after}", tmp_path)
    assert done.stdout.startswith("VERDICT: the ball's form explains the misfit"), done.stdout[:300]


def test_the_follow_up_plan_of_a_form_tie_turns_the_ball(seed_machine):
    """``diagnose --plan`` of the tie: the path again with the ball turned 60° on its stem (a
    mounting's minutes besides the program's), and the pair it is to tell apart, the machine
    effect against the ball's form (their columns turned with the ball), told apart above
    0.13 µm with it, above 0.78 µm by the data alone (where the 0.8 µm form tied)."""
    from compgen.planning.follow_up import follow_up
    from compgen.planning.plan import MOUNT_MINUTES
    poses = generate(seed_machine, ["K4", "K1", "K2"])
    data = [_session(seed_machine, poses, TABLE4, (0.8, 3, 0.4), 0.0, 3, "a.csv")]
    found = diagnose(seed_machine, data, identify(seed_machine, data), noise_um=NOISE_UM, advisor=Advisor)
    assert found.form_rival == "ball_lobes3", found.verdict
    plan = follow_up(seed_machine, data, found, NOISE_UM, "fit.json")
    (setup,) = plan.setups
    m = setup.proposal
    assert (m.label, m.name) == ("K2 with the ball turned 60° on its stem", "K2_TURNED")
    assert plan.minutes == pytest.approx(setup.minutes + MOUNT_MINUTES)
    (then,), (now,) = plan.told.apart, plan.default_told.apart
    assert then.pair == now.pair == (found.significant[0].effect, "ball_lobes3")
    assert max(then.above) * 1e3 < 0.2 and min(now.above) * 1e3 > 0.6, (then.above, now.above)


@pytest.mark.parametrize("said, refusal", [
    ("b.csv", "give the file and the degrees"),
    ("b.csv=0", "the turn is between −360 and 360° and not 0"),
    ("b.csv=nan", "the turn is between −360 and 360° and not 0"),
    ("c.csv=60", "is not among the fit's data"),
    ("a.csv=60", "the fit's first data file"),
])
def test_a_turn_said_wrong_is_refused_in_one_line(seed_machine, tmp_path, said, refusal):
    from conftest import SEED_MACHINE, run

    from compgen.data.rtest import format_rtest
    poses = generate(seed_machine, ["K4"])
    for name in ("a.csv", "b.csv"):
        (tmp_path / name).write_text(format_rtest(seed_machine, _session(seed_machine, poses, TABLE4,
                                                                         (0.0, 3, 0.0), 0.0, 1, name)))
    said = said.replace("a.csv", str(tmp_path / "a.csv")).replace("b.csv", str(tmp_path / "b.csv"))
    code, _, err = run("fit", "--machine", SEED_MACHINE, tmp_path / "a.csv", tmp_path / "b.csv",
                       "--ball-turned", said, "-o", tmp_path / "f.json")
    assert code == 2 and refusal in err and err.count("\n") == 1, err
    assert not (tmp_path / "f.json").exists()

