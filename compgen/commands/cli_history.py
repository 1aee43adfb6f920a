"""The history's commands: record, list, show, trend, export, import, fleet, and check."""


from __future__ import annotations

import json
import sys

import click

from ..configuration.machine_file import load_machine
from ..configuration.session import read_data, reload
from ..data.rtest import device_of
from ..errors import CompgenError, one_line
from ..files import read_text, write_atomically
from ..planning.advice import Advisor
from ..statistics.gate import fit_gate
from ..statistics.results import load_fit
from ..units import number
from .cli_common import DB, FILE, FORCE, MACHINE, OUTPUT, SERIAL, Finite, progress, said, warn


def history_store(db: str | None, create: bool = True):
    """The history store, closed with the command (whether it succeeds or refuses)."""
    from ..history.store import open_store  # the store only for the commands that use it
    store = open_store(db, create)
    click.get_current_context().call_on_close(store.close)
    return store


TEMPERATURE_C = (-50.0, 200.0)   # a hall, a coolant, a spindle: beyond these a unit or typing error
EVERY_DAYS_MAX = 3653.0       # ten years: a check due later is no plan (and the calendar ends)


@click.group("history")
def history_cmd():
    """A machine's calibrations over time: record, list, trend, export, fleet."""


@history_cmd.command("init")
@DB
@click.option("--grant", multiple=True, metavar="ROLE",
              help="PostgreSQL: let ROLE read and append (never update or delete). Repeatable.")
def history_init_cmd(db, grant):
    """Create or migrate the store (PostgreSQL: run as the schema's owner)."""
    from ..history.store import VERSION, init
    store, applied = init(db, tuple(grant))
    store.close()
    click.echo(f"{store.where}: schema {VERSION}"
               + (f" (applied {', '.join(map(str, applied))})" if applied else " (up to date)")
               + (f"; {', '.join(grant)} may read and append" if grant else ""))


def record_fit_file(db, fit_file, machine_file, serial, taken, device, operator, temperatures):
    from ..history import record_fit, taken_at
    taken = taken_at(taken)          # before a store is opened (or made) for it
    fit = load_fit(fit_file)
    machine, sets = reload(fit, machine_file)
    progress("checking that the fit explains its data")
    reasons = fit_gate(machine, sets, fit)
    temps = {}
    for item in temperatures:
        key, _, value = item.partition("=")
        if not key.strip() or not value:
            raise CompgenError(f"--temperature takes NAME=°C, not {item!r}",
                               hint="e.g. --temperature spindle=23.5")
        temps[key.strip()] = number(value, f"--temperature {key.strip()}", "")
        if not TEMPERATURE_C[0] <= temps[key.strip()] <= TEMPERATURE_C[1]:
            raise CompgenError(f"--temperature {key.strip()}={value}: no temperature of a machine or its "
                               f"hall ({TEMPERATURE_C[0]:g} to {TEMPERATURE_C[1]:g} °C)",
                               hint="give it in °C, e.g. --temperature spindle=23.5")
    measured = device_of(fit.data)
    if device is not None and device != measured:
        raise CompgenError(f"--device {device}, but the fit's data are {measured} data",
                           hint="leave --device out: the fit file says which device measured")
    store = history_store(db)
    fid = record_fit(store, fit, machine, serial=serial, taken=taken, device=measured, operator=operator,
                     temperatures=temps, verdict=reasons)
    return store, fit, fid, reasons


@history_cmd.command("add")
@click.argument("fit_file", type=FILE)
@click.option("--machine", "machine_file", type=FILE, default=None,
              help="The fit's machine file (default: its own).")
@SERIAL
@click.option("--date", "taken", default=None, help="When the data were measured (ISO 8601; default now).")
@click.option("--device", type=click.Choice(["rtest", "probe"]), default=None,
              help="The device that measured (default: what the fit file says; a contradiction is refused).")
@click.option("--operator", default="", help="Who measured.")
@click.option("--temperature", "temperatures", multiple=True, metavar="NAME=°C",
              help="A temperature during the measurement, e.g. --temperature hall=21.5. Repeatable.")
@DB
def history_add_cmd(fit_file, machine_file, serial, taken, device, operator, temperatures, db):
    """Record a calibration (a fit.json) in the machine's history."""
    store, fit, fid, reasons = record_fit_file(db, fit_file, machine_file, serial, taken, device, operator,
                                           temperatures)
    click.echo(f"recorded {fit.marker} as calibration #{fid} in {store.where}: "
               + ("accepted" if not reasons else "NOT accepted as a reference: " + "; ".join(reasons)))


@history_cmd.command("list")
@DB
def history_list_cmd(db):
    """Every machine in the store, with its number of fits and its last one."""
    from ..history import machines_text
    click.echo(machines_text(history_store(db, create=False)))


@history_cmd.command("show")
@MACHINE
@SERIAL
@DB
def history_show_cmd(machine_file, serial, db):
    """The machine's fits and edits, in time order."""
    from ..history import trend
    t = trend(history_store(db, create=False), load_machine(machine_file), serial)
    click.echo(f"{one_line(t.machine)}{f' ({one_line(t.serial)})' if t.serial else ''}")
    events = [(e.taken, f"  {e.taken[:16]}  {e.kind:<12}{one_line(e.marker)}  {e.device:<6}σ̂ "
                        f"{e.sigma_um:.3f} µm  {one_line(e.verdict)}") for e in t.entries]
    events += [(e["taken"], f"  {e['taken'][:16]}  edit        from {one_line(e['marker'])} for "
                            f"{e['controller']}: "
                            "corrects "
                            + (", ".join(e["corrects"]) or "nothing")) for e in t.edits]
    click.echo("\n".join(text for _, text in sorted(events, key=lambda x: x[0])))


@history_cmd.command("trend")
@MACHINE
@SERIAL
@click.option("--param", "params", default=None, help="Comma-separated location errors (default: all).")
@click.option("--plot", type=FILE, default=None, help="Also draw the trend into this PNG.")
@click.option("--json", "as_json", is_flag=True, help="Print the trend as JSON.")
@FORCE
@DB
def history_trend_cmd(machine_file, serial, params, plot, as_json, force, db):
    """Every location error over time (machine values: corrections written are counted),
    with its σ, the edits, and the steps and drifts flagged against [drift]."""
    from ..history import trend, trend_dict, trend_text
    names = [n.strip() for n in params.split(",") if n.strip()] if params else None
    machine = load_machine(machine_file)
    t = trend(history_store(db, create=False), machine, serial, names)
    if plot:
        from ..history import drift_limits
        from ..reports.plots import trend_png
        write_atomically(plot, trend_png(t, drift_limits(machine, t), machine.tolerances), force)
    click.echo(json.dumps(trend_dict(t), indent=2, ensure_ascii=False) if as_json else trend_text(t),
               nl=as_json)


@history_cmd.command("export")
@click.option("--machine", "machine_name", default=None, help="Only this machine (its name).")
@OUTPUT
@FORCE
@DB
def history_export_cmd(machine_name, output, force, db):
    """Every fit's parameters, one row each, as CSV; a .json file holds the whole history
    too (sessions, fits, edits, checks), which `history import` reads into another store."""
    from ..history import export_text
    store = history_store(db, create=False)
    count, text, left_out = export_text(store, machine_name, output.endswith(".json"))
    for row in left_out:
        warn(f"left out {row}: a row compgen cannot read, which an import would refuse")
    write_atomically(output, text, force)
    said(output, f"wrote {count} rows to {output}"
                 + (f"; {len(left_out)} unreadable row(s) left out (above)" if left_out else ""))


@history_cmd.command("import")
@click.argument("export_file", type=FILE)
@click.option("--same-machine", "same", multiple=True, metavar="NAME",
              help="A machine without a serial that this store holds too, under this name: it is the same "
                   "machine (without it such a machine is refused: a name alone may be another plant's).")
@DB
def history_import_cmd(export_file, same, db):
    """Append another store's history (a `history export -o H.json`) to this one, its origin
    recorded; refused if it is this store's own, was imported before, or shares a fit."""
    import hashlib

    from ..files import MAX_DATA_BYTES, json_object
    from ..history import check_export, import_history
    text, raw = read_text(export_file, "history export", limit=MAX_DATA_BYTES)   # a plant's years: 140 MB
    sha256 = hashlib.sha256(raw).hexdigest()
    del raw                                 # held once: 10 000 fits are 140 MB of text
    doc = json_object(text, "history export", export_file)
    del text
    check_export(doc, export_file)          # before a store is made for it
    store = history_store(db)
    counts = import_history(store, doc, sha256, export_file, same)
    click.echo(f"imported into {store.where}: " + ", ".join(f"{n} {k}" for k, n in counts.items()))


@history_cmd.command("fleet")
@click.option("--every-days", type=Finite(min=0, max=EVERY_DAYS_MAX, min_open=True), default=90.0,
              show_default=True, help="A check is due this long after a machine's last measurement (at most "
                                      "ten years).")
@click.option("--json", "as_json", is_flag=True)
@DB
def history_fleet_cmd(every_days, as_json, db):
    """Every machine's last calibration, check and edit, and when its next check is due."""
    from ..history import fleet
    rows = fleet(history_store(db, create=False), every_days)
    if as_json:
        click.echo(json.dumps({"format": "compgen.fleet/1", "machines": rows}, indent=2, ensure_ascii=False))
        return
    click.echo(f"{'machine':<40}{'serial':<14}{'calibrated':<12}{'checked':<12}{'check':<7}{'due':<12}")
    for r in rows:
        check = "-" if r["last_check_passed"] is None else ("pass" if r["last_check_passed"] else "FAIL")
        name, serial = one_line(r["machine"])[:39], one_line(r["serial"])[:13]
        click.echo(f"{name:<40}{serial:<14}{(r['last_calibration'] or '-')[:10]:<12}"
                   f"{(r['last_check'] or '-')[:10]:<12}{check:<7}{(r['due'] or '-'):<12}"
                   + ("OVERDUE" if r["overdue"] else "")
                   + (f"UNREADABLE: {one_line(r['unreadable'])}" if r.get("unreadable") else ""))


@click.command("check")
@MACHINE
@click.argument("data", nargs=-1, type=FILE, required=True)
@SERIAL
@click.option("--date", "taken", default=None, help="When the data were measured (ISO 8601; default now).")
@click.option("--operator", default="", help="Who measured.")
@click.option("--json", "as_json", is_flag=True, help="Print the check as JSON.")
@click.option("--machine-changed", is_flag=True,
              help="Check though the machine file changed since the calibration (a known change of a "
                   "tolerance or a limit); said in the check.")
@DB
def check_cmd(machine_file, data, serial, taken, operator, as_json, machine_changed, db):
    """Check a short measurement (K4 alone will do) against the machine's last accepted
    calibration: each location error's change with its σ, pass or fail, what to do next.
    The check is recorded in the history."""
    from ..history import (
        calibration_accepted,
        calibration_fit,
        check,
        fit_as_calibrated,
        last_calibration,
        record_check,
        taken_at,
    )
    machine = load_machine(machine_file)
    sets = [read_data(p, machine, warn=warn) for p in data]
    when = taken_at(taken)
    store = history_store(db, create=False)
    calibration, entries, edits = last_calibration(store, machine, serial, before=when)
    reference = calibration_fit(store, calibration)
    accepted = calibration_accepted(machine, calibration, reference)
    fit, model = fit_as_calibrated(machine, sets, reference, advisor=Advisor)
    result = check(machine, fit, sets, calibration, entries, edits, when, serial, machine_changed, model,
                   accepted)
    record_check(store, result, fit, machine, serial=serial, operator=operator)
    click.echo(json.dumps(result.summary(), indent=2, ensure_ascii=False) if as_json else result.text(),
               nl=as_json)
    if not result.passed:
        sys.exit(1)


