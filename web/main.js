// The page: reads render's choices from the URL (?scene=knot-box&mode=shadow&accel=bvh&
// res=256x256&eye=X,Y,Z&target=X,Y,Z&backend=auto|gpu|cpu), traces with the wasm module
// (WebGPU where the browser has it, the CPU otherwise) and draws into <canvas id="gridtrace">.
// For scripts and tests: document.body.dataset.frames is the number of frames drawn,
// .backend "webgpu" or "cpu", .error the message of an error, .view the last frame's camera
// as URL parameters (render takes the same values as --eye, --target, --up, --vfov).
import init, { Page, openWebGpu, scenes, modes, accels, backendOf } from './gridtrace_web.js';

const body = document.body;
const canvas = document.getElementById('gridtrace');
const overlay = document.getElementById('overlay');
const message = document.getElementById('message');

function fail(e) {
  const text = e instanceof Error ? e.message : String(e);
  body.dataset.error = text;
  message.textContent = 'error: ' + text;
}

// A turn of the event loop: WebGPU completes a frame's readback only there.
const nextTask = () => new Promise((resolve) => setTimeout(resolve, 0));

async function draw(page) {
  page.submit();
  while (!page.ready()) await nextTask();
  const frame = page.finish();
  canvas.width = frame.width;
  canvas.height = frame.height;
  const pixels = new Uint8ClampedArray(frame.rgba());
  canvas.getContext('2d').putImageData(new ImageData(pixels, frame.width, frame.height), 0, 0);
  body.dataset.view = page.view();
  body.dataset.frames = String(Number(body.dataset.frames || 0) + 1);
  body.dataset.firstFrameMs = body.dataset.firstFrameMs || frame.ms.toFixed(1);
  overlay.textContent = `${page.describe()}\n${frame.ms.toFixed(1)} ms a frame, ${frame.mraysPerS.toFixed(2)} Mrays/s`;
  if (frame.stages) overlay.textContent += `\n${frame.stages}`;
}

// The selectors list the library's registries, so a structure or mode added there shows here;
// a change reloads the page with the new query (the URL stays the page's whole state).
function fillSelectors(params) {
  const fill = (id, names, value) => {
    const select = document.getElementById(id);
    for (const n of names) select.add(new Option(n, n, false, n === value));
    select.addEventListener('change', () => {
      params.set(id, select.value);
      location.search = params.toString();
    });
  };
  fill('scene', scenes(), params.get('scene') || 'knot-box');
  fill('mode', modes(), params.get('mode') || 'trace');
  fill('accel', accels(), params.get('accel') || 'auto');
  fill('backend', ['auto', 'gpu', 'cpu'], params.get('backend') || 'auto');
}

async function main() {
  const t0 = performance.now();
  await init();
  const query = location.search;
  const params = new URLSearchParams(query);
  fillSelectors(params);
  let gpu;
  if (backendOf(query) !== 'cpu') {
    if (!navigator.gpu) {
      message.textContent = 'This browser has no WebGPU: tracing on the CPU, on one thread (slower).';
    } else {
      try {
        gpu = await openWebGpu();
      } catch (e) {
        message.textContent = `WebGPU is there but gave no device (${e.message}): tracing on the CPU.`;
      }
    }
  }
  const page = Page.open(query, gpu);
  const notes = page.notes();
  if (notes) message.textContent += (message.textContent ? '\n' : '') + notes;
  body.dataset.backend = page.backend();
  await draw(page);
  body.dataset.loadMs = (performance.now() - t0).toFixed(1);

  // Orbit (drag, one finger), pan (right or shift drag), zoom (wheel, two-finger pinch): each
  // redraws once the frame in progress is done, with all the input since folded into the
  // camera.
  let busy = false;
  let again = false;
  const redraw = async () => {
    if (busy) {
      again = true;
      return;
    }
    busy = true;
    try {
      do {
        again = false;
        await draw(page);
      } while (again);
    } catch (e) {
      fail(e);
    } finally {
      busy = false;
    }
  };
  // Pointers down on the canvas (mouse, pen or fingers), by id: two fingers pinch to zoom.
  const down = new Map();
  const apart = () => {
    const [a, b] = [...down.values()];
    return Math.hypot(a.x - b.x, a.y - b.y);
  };
  canvas.addEventListener('contextmenu', (ev) => ev.preventDefault());
  canvas.addEventListener('pointerdown', (ev) => {
    down.set(ev.pointerId, { x: ev.clientX, y: ev.clientY });
    canvas.setPointerCapture(ev.pointerId);
  });
  const lift = (ev) => down.delete(ev.pointerId);
  canvas.addEventListener('pointerup', lift);
  canvas.addEventListener('pointercancel', lift);
  canvas.addEventListener('pointermove', (ev) => {
    if (!ev.buttons) return;
    if (down.size === 2 && down.has(ev.pointerId)) {
      const before = apart();
      down.set(ev.pointerId, { x: ev.clientX, y: ev.clientY });
      page.pinch(apart() / before);
    } else if (down.size > 2) {
      return;
    } else if (ev.buttons & 2 || ev.shiftKey) page.pan(ev.movementX, ev.movementY);
    else page.orbit(ev.movementX, ev.movementY);
    redraw();
  });
  canvas.addEventListener('wheel', (ev) => {
    ev.preventDefault();
    page.zoom(-Math.sign(ev.deltaY));
    redraw();
  }, { passive: false });
  canvas.style.touchAction = 'none';

  const openFile = async (file) => {
    try {
      page.openMesh(file.name, new Uint8Array(await file.arrayBuffer()));
      body.dataset.backend = page.backend();
      await draw(page);
    } catch (e) {
      fail(e);
    }
  };
  document.getElementById('file').addEventListener('change', (ev) => openFile(ev.target.files[0]));
  body.addEventListener('dragover', (ev) => ev.preventDefault());
  body.addEventListener('drop', (ev) => {
    ev.preventDefault();
    if (ev.dataTransfer.files.length) openFile(ev.dataTransfer.files[0]);
  });
}

main().catch(fail);
