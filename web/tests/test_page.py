"""The web page in a real browser: Debian's Chromium, headless, driven by Playwright.

The page (web/dist, from scripts/build-web.sh) renders knot-box at 256x256 in shadow mode;
its canvas, read back as PNG, is compared with the native CLI's CPU render of the same camera:
at most 1% of pixels may differ. On the CPU tracer (the path without WebGPU) and on WebGPU
(SwiftShader's adapter): every mode and structure, a dropped mesh and an opened Stanford Bunny
PLY, each on both; the page without WebGPU says so and traces on the CPU; dragging, the wheel
and a two-finger pinch move the camera as render places it.

These tests sit beside the page rather than with the Python package's: they need no wheel,
only Playwright (from PyPI, no browser download), Pillow, numpy, the browser, web/dist and the
native CLI.

Environment: GRIDTRACE_BIN (default target/release/gridtrace), CHROMIUM (default
/usr/bin/chromium), GRIDTRACE_DATA_DIR (the mesh folder, for the bunny; default
../shared/data/meshes beside the checkout), GRIDTRACE_WEB_SCREENSHOT (a PNG path: the WebGPU case's page is saved there, as in the README).
Under CI=1 what is missing fails instead of skipping.

Run: scripts/test-web.sh (builds web/dist and the release CLI, then runs these), or
scripts/build-web.sh && python3 -m pytest -s web/tests
"""

import base64
import functools
import http.server
import io
import os
import pathlib
import subprocess
import tempfile
import threading

import numpy as np
import pytest
from PIL import Image

ROOT = pathlib.Path(__file__).resolve().parents[2]
DIST = ROOT / "web" / "dist"
CLI = pathlib.Path(os.environ.get("GRIDTRACE_BIN", ROOT / "target" / "release" / "gridtrace"))
CHROMIUM = os.environ.get("CHROMIUM", "/usr/bin/chromium")
CI = os.environ.get("CI", "") not in ("", "0", "false")

# Flags that start Chromium on a machine without network or GPU (as root: no sandbox), with
# WebGPU on SwiftShader's software adapter.
FLAGS = [
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--enable-unsafe-webgpu",
    "--use-webgpu-adapter=swiftshader",
]

# The comparison's camera and image: knot-box's own camera, render's defaults otherwise.
QUERY = "scene=knot-box&mode=shadow&res=256x256"
# A pixel differs when a channel is off by more than this many 8-bit levels (the wasm build
# and the native one may round a shading term differently; a missed or extra hit is far more).
LEVELS = 2
MAX_DIFFERING = 0.01


def missing(why):
    if CI:
        pytest.fail(why)
    pytest.skip(why)


@pytest.fixture(scope="module")
def server():
    if not (DIST / "gridtrace_web_bg.wasm").exists():
        missing(f"{DIST} is not built (scripts/build-web.sh)")

    class Handler(http.server.SimpleHTTPRequestHandler):
        extensions_map = {**http.server.SimpleHTTPRequestHandler.extensions_map, ".wasm": "application/wasm"}

        def log_message(self, *args):
            pass

    httpd = http.server.ThreadingHTTPServer(("127.0.0.1", 0), functools.partial(Handler, directory=str(DIST)))
    threading.Thread(target=httpd.serve_forever, daemon=True).start()
    yield f"http://127.0.0.1:{httpd.server_address[1]}/"
    httpd.shutdown()


@pytest.fixture(scope="module")
def browser():
    try:
        from playwright.sync_api import sync_playwright
    except ImportError:
        missing("playwright is not installed (pip install playwright; no browser download needed)")
    if not os.path.exists(CHROMIUM):
        missing(f"no Chromium at {CHROMIUM}")
    with tempfile.TemporaryDirectory() as profile, sync_playwright() as p:
        # A persistent context is the way to give Chromium its own empty profile folder.
        context = p.chromium.launch_persistent_context(
            profile, executable_path=CHROMIUM, headless=True, args=FLAGS, ignore_default_args=["--headless=new"]
        )
        yield context
        context.close()


def native_render(*args, backend="cpu"):
    """The native CLI's render with `args` (on the CPU unless `backend` says), as an RGB array."""
    if not CLI.exists():
        missing(f"no native CLI at {CLI} (cargo build --release -p gridtrace-cli)")
    with tempfile.TemporaryDirectory() as d:
        out = pathlib.Path(d) / "ref.png"
        subprocess.run([str(CLI), "render", *args, "--backend", backend, "-o", str(out)], check=True, capture_output=True)
        return np.asarray(Image.open(out).convert("RGB"), dtype=np.int16)


@pytest.fixture(scope="module")
def reference():
    return native_render("--scene", "knot-box", "--mode", "shadow", "--res", "256x256")


def load(browser, url, hide_webgpu=False):
    """Opens the page and waits for its first frame (or its error); returns the page, with the
    canvas as an RGB array and the page's figures."""
    page = browser.new_page()
    if hide_webgpu:
        # A browser without WebGPU: no navigator.gpu.
        page.add_init_script("delete Navigator.prototype.gpu;")
    page.goto(url)
    page.wait_for_function("document.body.dataset.frames || document.body.dataset.error", timeout=120_000)
    error = page.evaluate("document.body.dataset.error")
    assert not error, f"the page failed: {error}"
    return page


def png_rgb(data_url):
    png = base64.b64decode(data_url.split(",", 1)[1])
    return np.asarray(Image.open(io.BytesIO(png)).convert("RGB"), dtype=np.int16)


def canvas_rgb(page):
    return png_rgb(page.evaluate("document.getElementById('gridtrace').toDataURL('image/png')"))


def differing(a, b):
    assert a.shape == b.shape, (a.shape, b.shape)
    return float((np.abs(a - b).max(axis=2) > LEVELS).mean())


def figures(page):
    d = page.evaluate("({...document.body.dataset})")
    return f"load {d.get('loadMs')} ms, first frame {d.get('firstFrameMs')} ms"


def test_cpu_page_matches_the_native_render(server, browser, reference):
    page = load(browser, f"{server}?{QUERY}&backend=cpu")
    assert page.evaluate("document.body.dataset.backend") == "cpu"
    assert page.evaluate("document.body.dataset.frames") == "1"
    frac = differing(canvas_rgb(page), reference)
    print(f"\ncpu: {frac:.4%} of pixels differ from the native CPU render; {figures(page)}")
    assert frac <= MAX_DIFFERING
    page.close()


def load_on(browser, url, backend):
    """`load` on the CPU tracer (`backend=cpu`), or on WebGPU (`backend=auto`): a page that found
    no WebGPU device fails under CI (SwiftShader's adapter is there with these flags) and skips
    elsewhere."""
    page = load(browser, f"{url}&backend={'cpu' if backend == 'cpu' else 'auto'}")
    got = page.evaluate("document.body.dataset.backend")
    if backend == "webgpu" and got != "webgpu":
        message = page.inner_text("#message")
        page.close()
        missing(f"this Chromium gave no WebGPU device: {message}")
    assert got == backend
    return page


BACKENDS = ["cpu", "webgpu"]


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize(
    "query",
    [f"mode={m}" for m in ("cast", "trace", "heat")] + [f"mode=shadow&accel={a}" for a in ("grid", "pc", "irregular", "brute")],
)
def test_every_mode_and_structure_matches_the_native_render(server, browser, query, backend):
    """The page's other choices, each against render given the same options (small frames). On
    WebGPU heat mode is compared with the native GPU render (lavapipe): its colours count the GPU
    walk's steps, which are not the CPU walk's."""
    page = load_on(browser, f"{server}?scene=mirror-spheres&res=96x72&{query}", backend)
    args = [a for kv in query.split("&") for a in (f"--{kv.split('=')[0]}", kv.split("=")[1])]
    native = "gpu" if (backend, query) == ("webgpu", "mode=heat") else "cpu"
    frac = differing(
        canvas_rgb(page), native_render("--scene", "mirror-spheres", "--res", "96x72", *args, backend=native)
    )
    print(f"\n{backend} {query}: {frac:.4%} of pixels differ; {figures(page)}")
    assert frac <= MAX_DIFFERING
    page.close()


def test_webgpu_page_matches_the_native_render(server, browser, reference):
    page = load_on(browser, f"{server}?{QUERY}", "webgpu")
    frac = differing(canvas_rgb(page), reference)
    overlay = page.inner_text("#overlay")
    print(f"\nwebgpu: {frac:.4%} of pixels differ from the native CPU render; {figures(page)}\n{overlay}")
    assert frac <= MAX_DIFFERING
    shot = os.environ.get("GRIDTRACE_WEB_SCREENSHOT")
    if shot:
        # The README's picture of the page.
        page.set_viewport_size({"width": 760, "height": 560})
        page.screenshot(path=shot)
    # The GPU's stage times, where the browser gives timestamp queries (SwiftShader does).
    stages = overlay.splitlines()[-1]
    assert stages == "GPU stage times: this browser gives no timestamp queries" or (
        stages.startswith("GPU ") and all(f"{k} " in stages for k in ("raygen", "traverse", "shade", "occlusion"))
    ), overlay
    page.close()


def test_without_webgpu_the_page_says_so_and_traces_on_the_cpu(server, browser, reference):
    page = load(browser, f"{server}?{QUERY}", hide_webgpu=True)
    assert page.evaluate("document.body.dataset.backend") == "cpu"
    assert "no WebGPU" in page.inner_text("#message")
    assert differing(canvas_rgb(page), reference) <= MAX_DIFFERING
    page.close()


# An adapter with WebGPU's default 8 storage buffers a stage (fewer than the shading kernel's
# 10): its limits object reports 8 (wgpu asks for what the adapter reports).
EIGHT_STORAGE_BUFFERS = """(() => {
    const limits = Object.getOwnPropertyDescriptor(GPUAdapter.prototype, 'limits').get;
    Object.defineProperty(GPUAdapter.prototype, 'limits', {
        get() {
            const real = limits.call(this);
            return new Proxy(real, {
                get: (target, key) => key === 'maxStorageBuffersPerShaderStage'
                    ? 8 : Reflect.get(target, key, target),
            });
        },
    });
})();"""


def test_an_adapter_with_too_few_storage_buffers_is_named_and_the_page_traces_on_the_cpu(server, browser, reference):
    page = browser.new_page()
    page.add_init_script(EIGHT_STORAGE_BUFFERS)
    page.goto(f"{server}?{QUERY}")
    page.wait_for_function("document.body.dataset.frames || document.body.dataset.error", timeout=120_000)
    assert not page.evaluate("document.body.dataset.error")
    if not page.evaluate("!!navigator.gpu"):
        page.close()
        missing("this Chromium has no WebGPU")
    message = page.inner_text("#message")
    assert page.evaluate("document.body.dataset.backend") == "cpu", message
    assert "allows 8 storage buffers per shader stage" in message and "needs 10" in message, message
    assert differing(canvas_rgb(page), reference) <= MAX_DIFFERING
    print(f"\n8 storage buffers: {message}")
    page.close()


def test_dragging_and_the_wheel_move_the_camera_as_render_places_it(server, browser):
    page = load(browser, f"{server}?scene=mirror-spheres&mode=shadow&res=160x120&backend=cpu")
    first = canvas_rgb(page)
    box = page.locator("#gridtrace").bounding_box()
    page.mouse.move(box["x"] + 80, box["y"] + 60)
    page.mouse.down()
    page.mouse.move(box["x"] + 120, box["y"] + 40, steps=4)
    page.mouse.up()
    page.mouse.wheel(0, -100)
    # One frame per input event, or fewer: input during a frame is folded into the next.
    page.wait_for_function("Number(document.body.dataset.frames) >= 2", timeout=60_000)
    page.wait_for_timeout(500)
    # The canvas and the camera it was drawn with, read in one go (a frame is drawn whole in
    # one task of the page's).
    shot = page.evaluate(
        "({png: document.getElementById('gridtrace').toDataURL('image/png'), view: document.body.dataset.view})"
    )
    view = dict(p.split("=", 1) for p in shot["view"].split("&"))
    moved = png_rgb(shot["png"])
    assert differing(first, moved) > 0.1, "the view did not move"
    # The page's camera, given to render: the same image.
    args = [a for k, v in view.items() for a in (f"--{k}", v)]
    frac = differing(moved, native_render("--scene", "mirror-spheres", "--mode", "shadow", "--res", "160x120", *args))
    print(f"\norbited: {frac:.4%} of pixels differ from render at {view}")
    assert frac <= MAX_DIFFERING
    page.close()


def distance(view):
    eye = np.array([float(x) for x in view["eye"].split(",")])
    target = np.array([float(x) for x in view["target"].split(",")])
    return float(np.linalg.norm(eye - target))


def test_a_two_finger_pinch_zooms_as_render_places_it(server, browser):
    page = load(browser, f"{server}?scene=mirror-spheres&mode=shadow&res=160x120&backend=cpu")
    start = dict(p.split("=", 1) for p in page.evaluate("document.body.dataset.view").split("&"))
    box = page.locator("#gridtrace").bounding_box()
    cx, cy = box["x"] + 80, box["y"] + 60
    # Real touches, as Chromium's input pipeline makes them (trusted pointer events).
    cdp = page.context.new_cdp_session(page)
    cdp.send("Emulation.setTouchEmulationEnabled", {"enabled": True, "maxTouchPoints": 2})

    def touch(kind, half):
        points = [] if kind == "touchEnd" else [
            {"x": cx - half, "y": cy, "id": 0},
            {"x": cx + half, "y": cy, "id": 1},
        ]
        cdp.send("Input.dispatchTouchEvent", {"type": kind, "touchPoints": points})

    touch("touchStart", 20)
    for half in (25, 30, 35, 40):
        touch("touchMove", half)
    touch("touchEnd", 40)
    page.wait_for_function("Number(document.body.dataset.frames) >= 2", timeout=60_000)
    page.wait_for_timeout(500)
    shot = page.evaluate(
        "({png: document.getElementById('gridtrace').toDataURL('image/png'), view: document.body.dataset.view})"
    )
    view = dict(p.split("=", 1) for p in shot["view"].split("&"))
    # The fingers went from 40 to 80 pixels apart: the scene twice as large, the eye at half
    # the distance (each finger's moves count; the spreads multiply to 2).
    ratio = distance(view) / distance(start)
    assert abs(ratio - 0.5) < 1e-3, (start, view)
    args = [a for k, v in view.items() for a in (f"--{k}", v)]
    frac = differing(png_rgb(shot["png"]), native_render("--scene", "mirror-spheres", "--mode", "shadow", "--res", "160x120", *args))
    print(f"\npinched: distance x{ratio:.4f}, {frac:.4%} of pixels differ from render at {view}")
    assert frac <= MAX_DIFFERING
    page.close()


def test_a_bad_parameter_is_an_error_on_the_page(server, browser):
    page = browser.new_page()
    page.goto(f"{server}?scene=teapot")
    page.wait_for_function("document.body.dataset.error", timeout=60_000)
    error = page.evaluate("document.body.dataset.error")
    assert "unknown scene 'teapot'" in error and "knot-box" in error, error
    assert "frames" not in page.evaluate("({...document.body.dataset})")
    page.close()


# A tetrahedron, as an OFF file.
TETRA_OFF = "OFF\n4 4 0\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n3 0 2 1\n3 0 1 3\n3 0 3 2\n3 1 2 3\n"

DROP = """([name, text]) => {
    const dt = new DataTransfer();
    dt.items.add(new File([text], name));
    document.body.dispatchEvent(new DragEvent('drop', {dataTransfer: dt, bubbles: true, cancelable: true}));
}"""


@pytest.mark.parametrize("backend", BACKENDS)
def test_a_dropped_mesh_renders_and_a_bad_one_says_where(server, browser, tmp_path, backend):
    page = load_on(browser, f"{server}?mode=shadow&res=96x72", backend)
    page.evaluate(DROP, ["tetra.off", TETRA_OFF])
    page.wait_for_function("document.body.dataset.frames === '2' || document.body.dataset.error", timeout=60_000)
    assert not page.evaluate("document.body.dataset.error")
    off = tmp_path / "tetra.off"
    off.write_text(TETRA_OFF)
    frac = differing(canvas_rgb(page), native_render("--mesh", str(off), "--mode", "shadow", "--res", "96x72"))
    assert frac <= MAX_DIFFERING, frac
    page.evaluate(DROP, ["bad.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 9\n"])
    page.wait_for_function("document.body.dataset.error", timeout=60_000)
    error = page.evaluate("document.body.dataset.error")
    assert "bad.obj" in error and "line 4" in error, error
    page.close()


@pytest.mark.parametrize("backend", BACKENDS)
def test_an_opened_bunny_renders(server, browser, backend):
    # The shared meshes beside the checkout, as the Rust tests read them, unless named.
    data = os.environ.get("GRIDTRACE_DATA_DIR") or ROOT.parent / "shared" / "data" / "meshes"
    bunny = pathlib.Path(data) / "bunny" / "bun_zipper.ply"
    if not bunny.exists():
        missing(f"no Stanford Bunny at {bunny} (GRIDTRACE_DATA_DIR names the mesh folder)")
    page = load_on(browser, f"{server}?mode=cast&res=128x128", backend)
    page.set_input_files("#file", str(bunny))
    page.wait_for_function("document.body.dataset.frames === '2' || document.body.dataset.error", timeout=120_000)
    assert not page.evaluate("document.body.dataset.error")
    overlay = page.inner_text("#overlay")
    # The same auto-framed scene (the mesh over a floor) as render --mesh.
    frac = differing(canvas_rgb(page), native_render("--mesh", str(bunny), "--mode", "cast", "--res", "128x128"))
    print(f"\nbunny ({backend}): {frac:.4%} of pixels differ from the native CPU render; {overlay}")
    assert overlay.startswith("bun_zipper.ply: "), overlay
    assert frac <= MAX_DIFFERING
    page.close()
