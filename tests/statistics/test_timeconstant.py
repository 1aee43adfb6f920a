"""A saturating effect's time constant fitted: a warming whose τ lies between the catalogue's
5, 15 and 45 min is named at its own τ (and its equivalent beside it), adding it brings the
fit to the noise with the location errors within 3σ; a τ on the grid stays the grid's."""

import numpy as np
import pytest
from conftest import TABLE4, UM

from compgen.data.simulate import simulate
from compgen.model.effects import compose, location_model
from compgen.model.paths import generate
from compgen.statistics.diagnose import diagnose
from compgen.statistics.identify import identify

NOISE_UM = 0.5


def _named(found) -> set[str]:
    return {found.significant[0].effect, *found.rivals}


def test_a_warming_off_the_grid_is_named_at_its_own_time_constant(seed_machine):
    """τ = 8 min: named at 8 ± 1.6 (with its equivalent, drift_X at the same τ); added, the
    location errors within 3σ (at the grid's 5 or 15 they ended 3.1σ off)."""
    poses = generate(seed_machine, ["K4", "K1", "K2"])
    truth = {**TABLE4, "XOC:e8": 6 * UM}
    data = [simulate(seed_machine, truth, poses, NOISE_UM, np.random.default_rng(3))]
    found = diagnose(seed_machine, data, identify(seed_machine, data), noise_um=NOISE_UM)
    named = _named(found)
    taus = {float(n.split(":e")[1]) for n in named if ":e" in n}
    assert len(taus) == 1 and abs(taus.pop() - 8) <= 1.6 and "XOC:e" in " ".join(named), named
    _within_3_sigma(seed_machine, data, found.significant[0].effect)


def test_a_warming_between_two_grid_constants_ends_within_3_sigma(seed_machine):
    """τ = 30 min, between 15 and 45: named at its own τ where the data tell it from the
    grid's, else at the grid's; either added leaves the location errors within 3σ."""
    poses = generate(seed_machine, ["K4", "K1", "K2"])
    data = [simulate(seed_machine, {**TABLE4, "XOC:e30": 6 * UM}, poses, NOISE_UM, np.random.default_rng(3))]
    found = diagnose(seed_machine, data, identify(seed_machine, data), noise_um=NOISE_UM)
    _within_3_sigma(seed_machine, data, found.significant[0].effect)


def _within_3_sigma(machine, data, best):
    fit = identify(machine, data, compose(machine, location_model(machine), [best]))
    assert fit.residual["sigma_um"] == pytest.approx(NOISE_UM, rel=0.1)
    off = {n: abs(fit.parameters[n].value - v) / fit.parameters[n].std for n, v in TABLE4.items()}
    assert max(off.values()) < 3, (best, off)


def test_a_warming_on_the_grid_keeps_the_grids_time_constant(seed_machine):
    poses = generate(seed_machine, ["K4", "K1", "K2"])
    data = [simulate(seed_machine, {**TABLE4, "XOC:e15": 6 * UM}, poses, NOISE_UM, np.random.default_rng(3))]
    found = diagnose(seed_machine, data, identify(seed_machine, data), noise_um=NOISE_UM)
    assert "XOC:e15" in _named(found) and not any(":e" in n and not n.endswith(("e5", "e15", "e45"))
                                                  for n in _named(found)), _named(found)


def test_a_warmings_time_constant_the_data_cannot_fix_widens_the_sigma_it_moves():
    """On the fork head XOC moves by ~3σ per minute of a warming's τ: fitted with XOC:e9 where
    the truth is XOC:e8, the plain fit leaves XOC several σ off; the budget tries the τ the
    data do not tell from 9 (choices) and its σ then holds the truth."""
    from conftest import ARCSEC, FORK_MACHINE

    from compgen.configuration.machine_file import load_machine
    from compgen.statistics.budget import with_budget
    machine = load_machine(FORK_MACHINE)
    truth = {"XOW": 3 * UM, "YOW": -5 * UM, "ZOW": 4 * UM, "XOC": 6 * UM, "YOC": -8 * UM, "AOC": 5 * ARCSEC,
             "BOC": -4 * ARCSEC, "XOB": 10 * UM, "ZOB": -7 * UM, "AOB": 6 * ARCSEC, "COB": -8 * ARCSEC}
    data = [simulate(machine, {**truth, "XOC:e8": 6 * UM}, generate(machine, list(machine.paths)), NOISE_UM,
                     np.random.default_rng(11))]
    plain = identify(machine, data, compose(machine, location_model(machine), ["XOC:e9"]))
    held = with_budget(machine, data, plain, noise_um=NOISE_UM)
    assert any(any(e.startswith("XOC:e") for e in c["equivalents"]) for c in held.choices), held.choices
    assert held.parameters["XOC"].std > 2 * plain.parameters["XOC"].std
    assert abs(held.parameters["XOC"].value - truth["XOC"]) < 3 * held.parameters["XOC"].std


def test_two_drifts_in_time_are_told_apart_beside_each_other(seed_machine):
    """YOC 4 µm/h and AOC 6″/h drifting linearly, K4 + K1 + K2 run back to back: alone, the
    warming AOC:e45 removes nine tenths of what AOC:t1 removes, a rival while YOC's drift is
    left unexplained; judged each beside the second effects, AOC:t1 removes more by far over
    82 minutes (found), not over 55 (still a tie: the data cannot say yet)."""
    from conftest import ARCSEC

    from compgen.model.poses import Poses
    poses = generate(seed_machine, ["K4", "K1", "K2"])
    truth = {**TABLE4, "YOC:t1": 4 * UM, "AOC:t1": 6 * ARCSEC}
    for files, named in ((2, None), (3, "AOC:t1")):
        rng = np.random.default_rng(0)
        data = [simulate(seed_machine, truth, Poses(poses.q, poses.ball, poses.t + k * (poses.t.max() + 20),
                                                    poses.path), NOISE_UM, rng) for k in range(files)]
        found = diagnose(seed_machine, data, identify(seed_machine, data), noise_um=NOISE_UM)
        assert found.significant[0].effect == "AOC:t1" and found.found == named, (files, found.rivals)
        assert named or "AOC:e45" in found.rivals


def test_a_scale_warming_as_its_axis_works_is_named_and_added_within_3_sigma(seed_machine):
    """A's scale growing in time (3″ per radian of A, τ = 15 min): named found at its τ, not
    as a warming of A's location or a plain scale; added, the fit at the noise and the
    location errors within 3σ."""
    from conftest import ARCSEC
    poses = generate(seed_machine, ["K4", "K1", "K2"])
    truth = {**TABLE4, "EAA:g15": 3 * ARCSEC}
    data = [simulate(seed_machine, truth, poses, NOISE_UM, np.random.default_rng(3))]
    found = diagnose(seed_machine, data, identify(seed_machine, data), noise_um=NOISE_UM)
    assert found.found == "EAA:g15", (found.verdict, [c.effect for c in found.significant[:3]], found.rivals)
    _within_3_sigma(seed_machine, data, found.found)


def test_one_error_growing_by_shapes_no_set_up_parts_is_measured_again_later(seed_machine):
    """AOC growing as t² (no candidate's shape): over one K4 + K1 + K2, AOC:t1 and AOC:e45 tie
    and no single set-up of the machine parts them at their sizes. They are one error's two
    shapes in time: the advice is the repeat right after these data, said to part none at
    their sizes alone (it said no set-up tells them apart and that the cause needs another
    reference). Followed as printed, each repeat in a file of its own, the loop ends naming
    AOC in time or unexplained once the repeat is in the data three times, never another
    error."""
    from conftest import ARCSEC

    from compgen.planning.advice import Advisor
    from compgen.statistics.diagnose_text import report
    poses = generate(seed_machine, ["K4", "K1", "K2"])
    truth = {**TABLE4, "AOC:t2": 4 * ARCSEC}
    data = [simulate(seed_machine, truth, poses, NOISE_UM, np.random.default_rng(7))]
    found = diagnose(seed_machine, data, identify(seed_machine, data), noise_um=NOISE_UM, advisor=Advisor)
    text = report(found)
    assert text.startswith("VERDICT: not told apart: AOC:t1 vs AOC:e45; measure: K4 again, right after these "
                           "data"), text.splitlines()[0]
    assert "(parts none at their sizes here: their shapes grow apart in time" in text
    assert "it needs another reference" not in text
    for seed in range(8, 14):
        m = found.rivals_separated_by[0]
        assert m.again and m.path == "K4", m.label
        data.append(simulate(seed_machine, truth, m.poses, NOISE_UM, np.random.default_rng(seed)))
        found = diagnose(seed_machine, data, identify(seed_machine, data), noise_um=NOISE_UM, advisor=Advisor)
        if found.verdict != "rivals":
            break
    assert (found.found or "").startswith("AOC:") or (found.unexplained and found.exhausted), \
        (found.verdict, found.found, found.rivals)
