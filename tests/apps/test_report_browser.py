"""``report.html`` opened in a real browser: headless Chromium (Debian's ``chromium``, installed
by ``make system-deps``) loads the report of the shipped image example with no console message
(the page has no script: any message is an error), renders the verdict and every panel in its
DOM, and takes a 1280×900 screenshot. Skipped only when chromium is not installed."""

import re
import shutil
import struct
import subprocess

import pytest

from handeye_drake.apps.cli import main

from .test_calibrate import IMAGES

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
pytestmark = pytest.mark.skipif(CHROMIUM is None, reason="chromium is not installed (as root: "
                                "make system-deps, or apt-get install chromium)")
#: What Chromium writes to its stderr log for console messages and uncaught exceptions.
CONSOLE = re.compile(r"CONSOLE|Uncaught|ERR_FILE_NOT_FOUND|net::ERR_")


def _chromium(tmp_path, page, *action):
    """(stdout, stderr log) of headless Chromium on ``page`` with ``action`` (--screenshot=…,
    --dump-dom); a fresh profile under tmp_path, nothing fetched from the network."""
    profile = tmp_path / f"profile{len(list(tmp_path.glob('profile*')))}"
    cmd = [CHROMIUM, "--headless", "--no-sandbox", "--disable-gpu",
           "--disable-background-networking", "--disable-component-update", "--disable-sync",
           "--no-first-run", f"--user-data-dir={profile}", "--enable-logging=stderr", "--v=0",
           "--window-size=1280,900", *action, page.as_uri()]
    done = subprocess.run(cmd, capture_output=True, text=True, timeout=120, cwd=tmp_path)
    return done.stdout, done.stderr


def console_errors(log: str) -> list[str]:
    return [line for line in log.splitlines() if CONSOLE.search(line)]


def _png_size(path):
    data = path.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    return struct.unpack(">II", data[16:24])


@pytest.fixture(scope="module")
def report(tmp_path_factory):
    out = tmp_path_factory.mktemp("browser") / "out"
    code = main(["calibrate", "--images", str(IMAGES), "--robot", str(IMAGES / "robot_poses.tum"),
                 "--target", "charuco:7x5:0.04:0.03:DICT_5X5_100", "--intrinsics",
                 str(IMAGES / "intrinsics.yaml"), "--out", str(out)])
    assert code == 0
    return out / "report.html"


def test_the_report_loads_without_console_errors_and_is_screenshotted(report, tmp_path):
    shot = tmp_path / "report.png"
    _, log = _chromium(tmp_path, report, f"--screenshot={shot}")
    assert console_errors(log) == [], console_errors(log)
    assert shot.exists() and _png_size(shot) == (1280, 900)
    assert shot.stat().st_size > 20_000  # a rendered page, not a blank one
    dom, log = _chromium(tmp_path, report, "--dump-dom")
    assert console_errors(log) == []
    assert "verdict: OK" in dom and "X_EC: camera C in the end-effector" in dom
    assert len(re.findall(r'class="panel" id="img-\d+"', dom)) == 14
    assert dom.count("<svg") >= 14


def test_the_console_check_sees_a_script_error(tmp_path):
    """The log parsing above is not vacuous: a page that throws is caught."""
    bad = tmp_path / "bad.html"
    bad.write_text("<!DOCTYPE html><html><body><p>x</p><script>throw new Error('boom')"
                   "</script></body></html>")
    _, log = _chromium(tmp_path, bad, f"--screenshot={tmp_path / 'bad.png'}")
    assert any("Uncaught Error: boom" in line for line in console_errors(log))
