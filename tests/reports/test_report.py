"""The HTML report (opened in headless Chromium), the checklist, templates in the wheel."""

import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from conftest import ROOT, SEED_MACHINE, run

SESSION = ROOT / "examples" / "seed-session.csv"


@pytest.fixture(scope="module")
def work(tmp_path_factory):
    folder = tmp_path_factory.mktemp("work")
    assert run("fit", "--machine", SEED_MACHINE, SESSION, "-o", folder / "fit.json")[0] == 0
    assert run("fit", "--from", folder / "fit.json", "--add", "EXC:h2", "-o", folder / "fit2.json")[0] == 0
    return folder


def test_report_is_self_contained_and_complete(work):
    out = work / "report.html"
    code, _, err = run("report", "--from", work / "fit2.json", "--before", work / "fit.json", "-o", out)
    assert code == 0, err
    html = out.read_text()
    # measured vs model on K4, K1, K2; the residual against A, C, X, Y, Z
    assert html.count("data:image/png;base64,") == 8 and "http" not in html.replace("https://", "")
    for part in ("Identified parameters", "Correlations", "Diagnose", "After the kinematics edit",
                 "Commissioning checklist", "EXC:h2c", "predicted"):
        assert part in html, part
    code, _, err = run("report", "--from", work / "fit2.json", "-o", out)
    assert code == 2 and "--force" in err


def test_report_numbers_say_what_they_are(work):
    """The caption names the RMS it shows; each path has its tolerance and verdict; a
    p-value below double precision is not printed as 0."""
    out = work / "captions.html"
    assert run("report", "--from", work / "fit.json", "-o", out)[0] == 0
    html = out.read_text()
    assert "largest RMS" not in html and "RMS over dX, dY and dZ together" in html
    for path, tol in (("K4", "10"), ("K1", "8"), ("K2", "8")):
        assert re.search(rf"<td class=\"l\">{path}</td>(<td>[^<]*</td>){{3}}<td>{tol}</td><td class=\"l\">"
                         r"(within|BEYOND)</td>", html), path
    assert "&lt; 1e-300" in html and not re.search(r"<td>0</td><td class=\"l\">significant", html)


def _chromium():
    return shutil.which("chromium") or shutil.which("chromium-browser")


def test_report_screenshot_in_headless_chromium_is_not_blank(work, tmp_path):
    browser = _chromium()
    if browser is None:
        if os.environ.get("COMPGEN_REQUIRE_BROWSER"):
            pytest.fail("chromium is not installed, and CI requires it")
        pytest.skip("chromium is not installed")
    out = work / "report-shot.html"
    assert run("report", "--from", work / "fit2.json", "-o", out, "--force")[0] == 0
    shot = tmp_path / "shot.png"
    subprocess.run([browser, "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic",
                    "--no-first-run", "--disable-background-networking", "--disable-component-update",
                    "--disable-sync", f"--user-data-dir={tmp_path / 'profile'}", "--window-size=1100,1600",
                    f"--screenshot={shot}", out.as_uri()], capture_output=True, timeout=120, check=True)
    from matplotlib.image import imread
    pixels = imread(shot)[..., :3]
    not_white = (pixels < 0.95).any(axis=-1).mean()
    assert pixels.shape[0] >= 1000 and not_white > 0.05, not_white   # text, tables and plots drawn
    assert pixels.std() > 0.05


def test_checklist_ticks_from_artefacts_and_names_the_next_step(work):
    code, out, err = run("checklist", "--machine", SEED_MACHINE, "--dir", work)
    assert code == 0, err
    assert "[x] Fit" in out and "[x] K4, K1, K2 measured" in out   # the fit names its data
    assert "[ ] Measurement programs written" in out
    # the hint runs compgen when pasted into bash (a bare `compgen` is bash's builtin), and
    # writes into the work folder
    nxt = re.search(r"Next: `(.*) measure-program (.*)`", out)
    assert nxt and nxt[1] != "compgen" and nxt[1].split()[-1] in ("compgen", "compgen-cli"), out
    assert f"-o {work / 'RTEST.H'}" in nxt[2], nxt[2]
    assert "(by hand) Sign-off" in out and "[x] Sign-off" not in out
    assert run("measure-program", "--machine", SEED_MACHINE, "--path", "K4", "-o", work / "K4.H")[0] == 0
    code, out, _ = run("checklist", "--machine", SEED_MACHINE, "--dir", work)
    assert "[x] Measurement programs written" in out and f"diagnose --from {work / 'fit2.json'}" in out
    code, _, err = run("checklist", "--machine", SEED_MACHINE, "--dir", work / "nope")
    assert code == 2 and "no such folder" in err


def test_templates_ship_inside_the_installed_package(tmp_path):
    """Run from outside the checkout: an installed wheel must carry compgen/templates."""
    code = ("import compgen, compgen.controllers as e, pathlib; "
            "print(pathlib.Path(compgen.__file__).parent); print(e.template_dir())")
    done = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, capture_output=True, text=True,
                          env={k: v for k, v in os.environ.items() if k != "PYTHONPATH"}, check=True)
    package, templates = done.stdout.split()
    # a source checkout (an editable install, or this copy) serves its top-level templates/;
    # an installed wheel its own compgen/templates
    checkout = (Path(package).parent / "pyproject.toml").exists()
    assert Path(templates) == (Path(package).parent if checkout else Path(package)) / "templates", templates
    assert (np.array([p for p in os.listdir(templates)]) == "unconfirmed.j2").any()


def test_report_says_what_diagnose_cannot_decide(tmp_path):
    """Rivals, correlated noise and an outlier reach the report's words and its plots."""
    truth = tmp_path / "truth.json"
    truth.write_text('{"parameters": {"EXX:p1": {"value": 10, "unit": "um"}}}')
    data = tmp_path / "s.csv"
    assert run("simulate", "--machine", SEED_MACHINE, "--truth", truth, "--noise-um", 0.5, "--noise-rho",
               0.5, "--seed", 3, "-o", data)[0] == 0
    lines = data.read_text().splitlines()
    head = [i for i, line in enumerate(lines) if line.startswith("path,")][0]
    cells = lines[head + 100].split(",")
    dx = lines[head].split(",").index("dX")
    cells[dx] = f"{float(cells[dx]) + 25:.6f}"
    lines[head + 100] = ",".join(cells)
    data.write_text("\n".join(lines) + "\n")
    assert run("fit", "--machine", SEED_MACHINE, data, "-o", tmp_path / "fit.json")[0] == 0
    out = tmp_path / "r.html"
    code, _, err = run("report", "--from", tmp_path / "fit.json", "-o", out)
    assert code == 0, err
    html = out.read_text()
    assert f"s.csv:{head + 101}" in html and "AR(1)" in html and "Not told apart" in html
    assert 'alt="rivals.png"' in html
