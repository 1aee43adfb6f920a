"""diagnose's words: the report a person reads, each command in it as it runs pasted into bash."""

from __future__ import annotations

import shlex
from itertools import combinations

from .. import me
from ..model.effects import effect_name, one_error_in_time
from ..units import three, three_header
from .advising import Proposal
from .diagnosis import REPEATS_TRIED, Diagnosis
from .significance import said_p


def report(d: Diagnosis, fit_path: str = "fit.json", top: int = 8) -> str:
    """The diagnosis as text: residual, candidates, rivals, what these data cannot see, and
    the next command for each."""
    fit, after = shlex.quote(fit_path), shlex.quote(next_name(fit_path))
    lines = [conclusion(d, fit, after), f"compgen diagnose: {d.machine}",
             f"  fit {d.fit_file}: {len(d.model)} parameters; residual RMS {d.rms_um:.3f} µm "
             f"(σ̂ {d.sigma_um:.3f} µm) over {d.readings} readings", "",
             f"  {'residual per path (µm)':<24}{three_header(('RMS dX', 'dY', 'dZ'))}"]
    lines += _residuals(d)
    lines += _candidates(d, fit, after, top)
    lines += _devices(d)
    lines += _form(d, fit, after)
    lines += _rivals_text(d, fit, after)
    if d.significant and not d.rivals and not d.unexplained and d.device_noise_um is None:
        lines += ["", f"  Not named as found: the R-test's noise is not given, so whether "
                      f"{d.significant[0].effect} leaves no more than noise cannot be tested (σ̂ is "
                      "these data's own scatter, which an effect outside the catalogue inflates too). "
                      "Set [rtest] noise_um in the machine file (the device's calibration), or "
                      "--noise-um, and diagnose again."]
    lines += _lines_text(d)
    if d.unexplained:
        lines += _unexplained(d, fit, after)
    elif not d.significant:
        lines += ["", "  No candidate is significant: the model explains these data to the "
                  + (f"{_device(d)} noise ({d.device_noise_um:.3g} µm)." if d.device_noise_um is not None else
                     f"noise level (their own scatter, σ̂ {d.sigma_um:.2f} µm). The R-test's noise is not "
                     "given: set [rtest] noise_um in the machine file, or --noise-um, to test the "
                     "residual against it.")]
    elif len(d.significant) > 1:
        best = d.significant[0].effect
        lines += ["", f"  Effects share misfit: once {best} is added, "
                      + (f"still significant: {', '.join(d.after_best)}." if d.after_best
                         else "no other candidate stays significant.")
                      + " Add one effect at a time and diagnose again."]
    lines += _unseen(d, fit, after)
    return "\n".join([*lines, *d.notes]) + "\n"


def _residuals(d: Diagnosis) -> list[str]:
    """The residual per path and against each axis, the outliers left out, the noise's
    correlation."""
    lines: list[str] = []
    for name, p in d.per_path.items():
        lines.append(f"    {name:<22}{three(p['rms_um'])}")
    if d.outliers:
        lines += ["", f"  {len(d.outliers)} outlying reading{'s' if len(d.outliers) > 1 else ''} "
                      "(a step from their neighbours), left out of the tests below; check them, "
                      "and delete their rows to leave them out of the fit too:"]
        lines += [f"    {o['file']}:{o['line'] or '?'}  path {o['path'] or '(unlabelled)'}  "
                  f"{o['size_um']:.1f} µm" for o in d.outliers]
    if any(any(v) for v in d.noise.values()):
        lines += ["", "  the noise is correlated from reading to reading: AR(1) ρ per path (dX dY dZ), "
                      "one standard error above its estimate: "
                  + "; ".join(f"{k} {' '.join(f'{v:.2f}' for v in p)}" for k, p in d.noise.items()),
                  "  the tests below are made on readings made white with it (generalised least squares; "
                  "at the estimate itself its error would flag clean data more often than α)"]
    lines += ["", "  residual against axis position (µm, amplitude in dX dY dZ)"]
    for axis, a in d.per_axis.items():
        for term, amp in a.items():
            lines.append(f"    {axis:<3}{term:<19}{three(amp)}")
    return lines


def _candidates(d: Diagnosis, fit: str, after: str, top: int) -> list[str]:
    """The visible candidates, most residual removed first, each with what to do about it."""
    lines: list[str] = []
    visible = [c for c in d.candidates if c.visible]
    lines += ["", f"  candidate effects, most residual removed first ({d.tested} tried; F test, "
                  f"Bonferroni-corrected, α = {d.alpha:g}):"]
    for i, c in enumerate(visible[:top], 1):
        amp = " ".join(f"{a:+.2f}" for a in c.amplitude)
        verdict = "SIGNIFICANT" if c.significant else "not significant"
        p = said_p(c.p_value)
        lines.append(f"  {i:>2}. {c.effect:<12} RMS → {c.rms_after_um:.3f} µm   {p}  {verdict}")
        lines.append(f"      {_said(d, c.description)} (≈ {amp} {c.unit}); likely cause: {c.cause}")
        if c.confounded_with:
            lines.append(f"      partly absorbed by {', '.join(c.confounded_with)}")
        if c.effect in d.equivalents or (d.equivalents and c is d.significant[0]):
            lines.append("      one column with the others marked so: the same on every set-up (see below)")
        elif d.rivals and (c.effect in d.rivals or c is d.significant[0]):
            lines.append("      not told apart from the others marked so: see below")
        elif c.significant and d.unexplained:
            lines.append("      it fits a part of the unexplained misfit (see below): not advised on its own")
        elif c.significant and d.device_blamed:
            lines.append(f"      the device explains these data as well ({d.device_blamed}): see below")
        elif d.form_rival and c is d.significant[0]:
            lines.append(f"      the ball's form explains these data as well ({d.form_rival}): see below")
        elif d.step_rivals and c is d.significant[0]:
            lines.append(f"      {d.setup_step.text()} explains these data as well: not named found "
                         "(see the first line)")
        elif c.significant and c.separable and c is not d.significant[0]:
            lines.append("      significant beside the best, with which it shares misfit: add the best "
                         "first, then diagnose again")
        elif c.significant and c.separable:
            lines.append(f"      add it: {me()} fit --from {fit} --add {c.effect} -o {after}")
        elif c.significant:
            lines.append(f"      seen, but not separable whole on these data (fit --add would refuse "
                         f"it: condition {c.condition:.3g}); "
                         + (f"measure {c.separated_by[0].label} first: {_measure(d, c.separated_by[0])}"
                            if c.separated_by else
                            "no set-up this machine can measure separates it"))
    return lines


def _rivals_text(d: Diagnosis, fit: str, after: str) -> list[str]:
    """The best's rivals: what would tell them apart, or why nothing does."""
    lines: list[str] = []
    if d.equivalents:
        best = d.significant[0].effect
        one = " ≡ ".join((best, *d.equivalents))
        lines += ["", f"  One column: {one} read the same on every set-up this machine can measure: one "
                      "candidate under several names. Adding one adds any of them, and the location errors "
                      "move alike; which physical cause it is (the names' causes above) needs another "
                      "reference.", *_carries(d)]
    if set(d.rivals) - set(d.equivalents):
        best = d.significant[0].effect
        verb = "explains" if len(d.rivals) == 1 else "explain"
        lines += ["", f"  Not told apart: {', '.join(d.rivals)} {verb} these data as well as "
                      f"{best}, within their noise; no one of them is named as found."]
        if d.device_blamed:
            lines.append("  Nor is any of them advised: the device explains these data as well (above).")
        elif d.rivals_separated_by:
            plan = d.rivals_separated_by
            told = set().union(*(_told(d, m) for m in plan))
            left = [p for p in combinations((d.significant[0].effect, *d.rivals), 2) if p not in told]
            lines.append(f"  To tell them apart, measure {'this' if len(plan) == 1 else 'these'}: "
                         + ("together they tell every pair apart" if not left else
                            "together they leave " + ", ".join(" / ".join(p) for p in left) + " open"))
            for i, m in enumerate(plan, 1):
                told = sorted(_told(d, m))
                lines.append(f"   {i}. {m.label} (" + (f"tells apart {', '.join(' / '.join(p) for p in told)}"
                             if told else "parts none at their sizes here: their shapes grow apart in time; "
                             "measure it, fit, diagnose, and again while they stay tied" if _in_time(d) else
                             f"parts none at their sizes here: the misfit is near the noise (p "
                             f"{d.significant[0].p_value:.2g} against the family's {d.alpha:g}); measured "
                             "again, a chance misfit fades and a real one grows; fit everything together "
                             "then") + ")")
                lines.append(f"      {_measure(d, m)}")
            lines += _then(plan, fit, after)
        elif not d.searched:             # no measurement was searched for (see the notes)
            lines += ["  Which measurement would tell them apart was not searched. Any one of them models "
                      f"the misfit: {me()} fit --from {fit} --add {best} -o {after}; the location errors "
                      "written to a control depend on the choice:", *_carries(d)]
        else:
            lines += ["  No path or ball position of the machine file tells them apart: for every "
                      "set-up compgen can measure, at its size here"
                      + (" (a probe's [probe] poses per path)" if d.data_device == "probe" else "")
                      + ", they predict readings closer than the noise tells apart (or the same: they "
                      "differ by what the location errors absorb). Any one of them models the misfit: "
                      f"{me()} fit --from {fit} --add {best} -o {after};",
                      "  which of them is the physical cause stays open ("
                      + ("they differ only in time: the same paths measured again later, the "
                         "R-test's clock running on, part them as they grow apart; fit everything "
                         "together then" if _in_time(d) else "it needs another reference")
                      + "), and the location errors written to a control depend on the choice:",
                      *_carries(d)]
    return lines


def _in_time(d: Diagnosis) -> bool:
    """Whether the best and its rivals are one error growing in time by different shapes."""
    return bool(d.significant) and one_error_in_time([d.significant[0].effect, *d.rivals])


def _unseen(d: Diagnosis, fit: str, after: str) -> list[str]:
    """What these data cannot see, the measurement that would show the most of it, and the
    fragile parameters."""
    lines: list[str] = []
    hidden = [c for c in d.candidates if not c.visible and (not c.silent or c.separated_by)]
    if hidden:
        lines += ["", "  not visible in these data (never reported as found; the fit absorbs them):"]
        for c in hidden:
            where = (f"would be seen with {' or '.join(m.label for m in c.separated_by[:3])}"
                     if c.separated_by
                     else "no path or ball position this machine can measure separates it: it "
                          "needs an independent reference")
            what = "moves no reading here" if c.silent else f"absorbed by {', '.join(c.confounded_with)}"
            lines.append(f"    {c.effect:<12} {_said(d, c.description)}: {what}; {where}")
        m, shows = d.next_measurement
        if m is not None:
            lines.append(f"  {'optional, the data being explained: ' if d.verdict == 'explained' else ''}"
                         f"to look for them, {m.label} would show the most ({len(shows)}: "
                         f"{', '.join(shows[:6])}{', …' if len(shows) > 6 else ''}):")
            lines.append(f"    {m.label}: {_measure(d, m)}")
            lines += _then([m], fit, after)
    silent = [c.effect for c in d.candidates if c.silent and not c.separated_by]
    if silent:
        lines += ["", "  no effect on any reading here (no lever arm to the nest or ball in this "
                      "machine file): " + ", ".join(silent)]
    lines += ["", "  fragile parameters: largest shift per µm (RMS over the poses) of an effect "
                  "not in the model"]
    for name, row in d.bias.items():
        per_um = {k: v / d.signature_um[k] for k, v in row.items() if d.signature_um[k] > 0}
        worst = max(per_um, key=lambda k: abs(per_um[k]), default=None)
        if worst is not None:
            lines.append(f"    {name:<6} {per_um[worst]:+6.2f} {d.bias_units[name]} per µm of "
                         f"{effect_name(worst)}")
    return lines


def _said(d: Diagnosis, words: str) -> str:
    """An effect's words for these data: a probe's set-up offset on the tool side is its
    stylus tip's, where an R-test's is its nest's."""
    return words.replace("R-test nest", "probe's stylus tip") if d.data_device == "probe" else words


def _noise_said(d: Diagnosis) -> str:
    """Where the noise the tests used came from, in words."""
    return {"given": f"the given noise {d.device_noise_um:.3g} µm ([rtest] noise_um or --noise-um)",
            "touches": f"the probe's noise {d.device_noise_um:.3g} µm, from its touches",
            "repeats": f"the noise {d.device_noise_um:.3g} µm from {d.repeats.words() if d.repeats else ''}",
            None: "no noise given"}[d.noise_from]


def conclusion(d: Diagnosis, fit: str, after: str) -> str:
    """The first line: what diagnose concludes, and the one next step."""
    best = d.significant[0].effect if d.significant else None
    add = f"{me()} fit --from {fit} --add {best} -o {after}"
    kind = d.verdict
    if kind == "device" and d.blamed.form:
        return (f"VERDICT: the ball's form explains the misfit ({d.blamed.description}, {d.blamed.text()}), "
                "not the machine: measure again on a round ball, or one whose form is known")
    if kind == "device":
        return (f"VERDICT: the device explains the misfit ({d.blamed.description}, {d.device_blamed}): "
                + ("calibrate the probe and probe again" if d.blamed.trigger else
                   "calibrate that sensor and measure again")
                + (f", or probe {d.probe_turned.path} with the probe turned {d.probe_turned.spindle:g}° in "
                   "the spindle (below)" if d.probe_turned else ""))
    if kind == "rivals" and d.form_rival:
        m = d.form_turned
        return (f"VERDICT: not told apart: {best} vs the ball's form ({d.form_rival}); "
                + (f"turn the ball {d.turn_degrees:g}° on its stem and measure {m.path} again (below)"
                   if m else "no program of this machine measures the ball turned on its stem (below)"))
    if kind == "set-up step":
        return (f"VERDICT: not told apart: {best} vs {d.setup_step.text()}; measure a path again right "
                "after these data without touching the ball or the nest: a warming or a drift goes on, a "
                "step does not")
    if kind == "found" and d.equivalents:
        return (f"VERDICT: found {' ≡ '.join((best, *d.equivalents))}, one column on every set-up this "
                "machine can measure (which is the cause needs another reference; against "
                f"{_noise_said(d)}); add it: {add}")
    if kind == "found":
        return f"VERDICT: found {best} (against {_noise_said(d)}); add it: {add}"
    if kind == "rivals":
        plan = d.rivals_separated_by
        return (f"VERDICT: not told apart: {' vs '.join((best, *d.rivals))}; "
                + (f"measure: {', '.join(m.label for m in plan)} (below)" if plan else
                   "they differ only in time: measure again later (below)" if _in_time(d) else
                   "no set-up of this machine tells them apart (below)"))
    if kind == "unexplained" and d.exhausted:
        return (f"VERDICT: unexplained: {' vs '.join((best, *d.rivals))} stay tied with "
                f"{' and '.join(d.exhausted)} measured {REPEATS_TRIED} times to tell them apart; something "
                "outside the shapes tried moves with them (below)")
    if kind == "unexplained":
        return ("VERDICT: unexplained: the residual exceeds the noise and no catalogue effect accounts for "
                "it; declare its shape (below)")
    if kind == "not separable":
        c = d.significant[0]
        return (f"VERDICT: {best} is seen but not separable whole on these data; "
                + (f"measure: {c.separated_by[0].label} (below)" if c.separated_by else
                   "no set-up of this machine separates it"))
    if kind == "noise unknown":
        return (f"VERDICT: {best or 'a misfit'} is the best explanation, but the noise is unknown, so "
                "nothing is named found: give --noise-um (the device's calibration), or measure a path "
                "twice, and diagnose again")
    if d.device_noise_um is None:
        return (f"VERDICT: explained to these data's own scatter (σ̂ {d.sigma_um:.2f} µm); the noise is "
                "unknown: give --noise-um, or measure a path twice, to test it")
    return f"VERDICT: explained to the noise ({_noise_said(d)}); nothing to add"


CARRIES_SHOWN = 0.2     # µm or ″: smaller shifts of a location error are not listed


def _carries(d: Diagnosis) -> list[str]:
    """What each equivalent choice puts into the fitted parameters, against the first."""
    if not d.carries:
        return []
    first = next(iter(d.carries))
    out = [f"  what each, added, moves in the fitted values (first order; the first, {first}, is the one "
           "the location errors absorb least):"]
    for name, shift in d.carries.items():
        big = [(n, v) for n, v in shift.items() if abs(v) >= CARRIES_SHOWN]
        out.append(f"    {name:<12} " + (", ".join(f"{n} {v:+.2f} {d.bias_units.get(n, '')}" for n, v in big)
                                         or f"nothing above {CARRIES_SHOWN:g} µm or ″"))
    return out


def _lines_text(d: Diagnosis) -> list[str]:
    """The residual's strongest periodic line against each coordinate."""
    if not d.lines:
        return []
    return ["", "  strongest periodic line of the residual against each axis and time:",
            *(f"    {line.text()}" for line in d.lines)]


def _unexplained(d: Diagnosis, fit: str, after: str) -> list[str]:
    """What no catalogue effect accounts for: where, its shape, and how a user who knows the
    cause declares it."""
    if d.exhausted:
        tied = (d.significant[0].effect, *d.rivals)
        runs = " and ".join(d.exhausted)
        return ["", f"  UNEXPLAINED: {' vs '.join(tied)} explain these data alike, and the runs advised "
                    f"to tell them apart ({runs}) are in the data {REPEATS_TRIED} times: "
                    "measuring again would not end this. What moves with them is outside the shapes tried "
                    "(two effects drifting at once, say, or a drift whose time constant is none of the "
                    "catalogue's). No edit should be written from these data (the gate refuses it); the "
                    "location errors may be off by what each would move them:", *_carries(d),
                "  measure again on a machine at a steady temperature (after its warm-up), or declare the "
                "effects you know and fit them together"]
    if d.misfit:
        out = ["", f"  UNEXPLAINED: the residual exceeds the {_device(d)} noise ({d.device_noise_um:.3g} µm) "
                   "and "
                   "no catalogue effect accounts for it:"]
        out += [f"    {m['direction']} of {m['path']}: RMS {m['rms_um']:.2f} µm (p = {m['p_value']:.2g})"
                for m in d.misfit[:6]]
    else:
        out = ["", "  UNEXPLAINED: a periodic line along a linear axis, a shape no catalogue effect has, "
                   "outweighs every candidate"]
    if d.significant:
        share = (f"only {d.best_share_of_excess:.0%} of the residual beyond the noise"
                 if d.best_share_of_excess is not None else "less than that line")
        out.append(f"  the best candidate, {d.significant[0].effect}, removes {share}: it is not named as "
                   "found.")
    worst = {m["direction"] for m in d.misfit}
    shape = d.outside_line or next((line for line in d.lines if line.direction in worst
                                    and line.p_value < d.alpha), None)
    if shape is None:
        out.append("  no periodic line against an axis or time stands out: look at the residual plots "
                   "(--plots) per path and axis")
        return out
    out.append(f"  its shape: {shape.text()}")
    if shape.unit == "mm":
        name = f"E{shape.direction[1]}{shape.against}:w{shape.period:.3f}"
        out += [f"  if its cause is known (a ball-screw or scale period of {shape.against}, say), declare it "
                "and fit again:", f"    {me()} fit --from {fit} --add {name} -o {after}",
                f"  or list it in the machine file (diagnose then tries it): [effects] declared = "
                f"[\"{name}\"]"]
    return out


def next_name(path: str) -> str:
    """The name of the next fit in the loop: fit.json → fit+1.json."""
    stem = path[:-5] if path.endswith(".json") else path
    return f"{stem}+1.json"


def _measure(d: Diagnosis, m: Proposal) -> str:
    command = m.command(me())
    # a remark after the command is a bash comment: the line pastes and runs as printed
    return command + ("  # then run it at once, the R-test's clock running on: its t column continues "
                      "these data's" if m.again else "")


def _told(d: Diagnosis, m: Proposal) -> set[tuple[str, str]]:
    """The pairs of rivals ``m`` tells apart on its own."""
    group = (d.significant[0].effect, *d.rivals)
    return set(combinations(group, 2)) - set(map(tuple, d.rivals_open.get(m.label, ())))


def _devices(d: Diagnosis) -> list[str]:
    """The R-test's own gains and the ball's form, where one is significant: blamed, or
    beside the machine's best."""
    seen = d.significant_devices
    if not seen:
        return []
    c = d.blamed
    if c is None:
        said = "; ".join(f"{o.text()} ({said_p(o.p_value)})" for o in seen)
        verb = "stays" if len(seen) == 1 else "stay"
        return ["", f"  The device: {said} {verb} significant beside the machine's effects (the best and "
                    "those significant beside it), which explain more: no device parameter is blamed for "
                    f"the misfit, but {_remedy(seen)} before these data correct a control, then measure "
                    "again."]
    than = f"as well as {d.significant[0].effect}" if d.significant else "where no machine effect does"
    size = f"{c.value:.2f} ± {c.std:.2f} µm" if c.unit == "µm" else f"{c.value:+.2f} ± {c.std:.2f} %"
    turned = d.probe_turned
    return ["", f"  The device: {c.description}, {size} ({c.effect}), explains these data {than}: no machine "
                "effect is named found, and nothing here corrects a control for it.",
            f"  {_remedy([c])[0].upper()}{_remedy([c])[1:]}, then measure again and fit the new data alone."
            + "".join(f" {o.text()} stays significant beside it ({said_p(o.p_value)}): "
                      + ("have the ball's form measured too." if o.form else "calibrate the probe too."
                         if o.trigger else "calibrate that sensor too.")
                      for o in seen if o is not c),
            *([f"  Or tell it from the machine: {turned.label} (the trigger turns with the probe, the "
               "machine does not), then fit both logs together:", f"      {_measure(d, turned)}"]
              if turned else [])]


def _remedy(devices) -> str:
    """What a user does about these device parameters: calibrate the sensors, replace the ball."""
    sensors = " and ".join(o.effect[-1] for o in devices if not o.form and not o.trigger)
    out = ([f"calibrate the R-test's {sensors} sensor{'s' if ' and ' in sensors else ''} against its "
            "reference (its calibration: [rtest] gain_u in the machine file)"] if sensors else [])
    if any(o.trigger for o in devices):       # the control's own cycle: its radius by direction
        out.append("calibrate the probe's trigger radius by direction on a reference sphere (the control's "
                   "3-D probe calibration), or probe again with the spindle oriented otherwise")
    if any(o.form for o in devices):
        out.append("measure on a round ball, or one whose form is known (its calibration certificate)")
    return " and ".join(out)


def _form(d: Diagnosis, fit: str, after: str) -> list[str]:
    """The ball's form tied with the machine's best, and the measurement that tells them apart."""
    if d.form_rival is None:
        return []
    form = next(o for o in d.devices if o.effect == d.form_rival)
    turn = f"{d.turn_degrees:g}"
    lines = ["", f"  The ball's form: {form.description} ({form.effect}, about {form.value:.2f} µm alone), "
                 f"reads on these paths as {d.significant[0].effect} does: these data cannot tell a ball "
                 "out of round from the machine, and neither is named. Turned on its stem, the ball's form "
                 f"turns with it and the machine does not ({turn}° reads the form the other way round)."]
    m = d.form_turned
    if m is None:
        return [*lines, "  No program of this machine measures the ball where it stands: have the ball's "
                        "form measured (its calibration certificate) before these data correct a control."]
    return [*lines, f"  Loosen the ball's clamp, turn the ball {turn}° on its stem without moving it, "
                    "tighten it, and run:",
            f"    {m.command(me())}",
            f"  save the R-test's readings as {m.name}.csv (the pose list beside the program, with dX dY "
            "dZ), then fit them with these data, saying the turn, and diagnose again:",
            f"    {me()} fit --from {fit} --data {m.name}.csv --ball-turned {m.name}.csv={turn} -o {after}"]


def _device(d: Diagnosis) -> str:
    if d.data_device == "probe":
        return "probe's (from its touches)"
    return f"repeats' ({d.repeats.words()})" if d.repeats else "R-test's"


def _then(ms, fit: str, after: str) -> list[str]:
    """What follows measurements: their readings into CSV files, added to the fit's data."""
    names = [m.name for m in ms]
    if ms and ms[0].device == "probe":
        logs = ", ".join(f"{n}.log" for n in names)
        return [f"  run {'it' if len(ms) == 1 else 'them'}; copy the probe log each writes on the control "
                f"(<program>_LOG) off as {logs}, then fit together with these data and diagnose again:",
                f"    {me()} fit --from {fit} " + " ".join(f"--data {n}.log" for n in names) + f" -o {after}"]
    csv = ", ".join(f"{n}.csv" for n in names)
    return [f"  run {'it' if len(ms) == 1 else 'them'}; save the R-test's readings as {csv} (the pose "
            "list beside each program, with dX dY dZ), then fit together with these data and diagnose again:",
            f"    {me()} fit --from {fit} " + " ".join(f"--data {n}.csv" for n in names) + f" -o {after}"]
