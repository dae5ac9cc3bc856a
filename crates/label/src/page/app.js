// travmap label's page: the asked frames from above, the model's call of each
// cell, the cells asked about; answers by click and by key, each saved by the server
// before it is shown as given. Plain script, no library: it is compiled into travmap.
"use strict";

const token = document.querySelector('meta[name="travmap-token"]').content;
const state = {
  session: null,
  frames: new Map(), // frame -> { view, image }
  answers: new Map(), // "frame:cell" -> answer
  asked: [], // [{ frame, cell, margin }] in the order asked
  askedIndex: new Map(), // "frame:cell" -> index in asked
  current: null, // { frame, cell }
  colouring: "height",
};

const $ = (id) => document.getElementById(id);
const key = (frame, cell) => `${frame}:${cell}`;
const words = { traversable: "traversable", not_traversable: "not traversable", skip: "can't tell" };

async function api(path, options = {}) {
  const headers = Object.assign({ "X-Travmap-Token": token }, options.headers || {});
  const response = await fetch(path, Object.assign({}, options, { headers }));
  if (!response.ok) {
    throw new Error(`${response.status}: ${await response.text()}`);
  }
  return response.json();
}

function say(text) {
  $("message").textContent = text;
}

async function frame(index) {
  if (!state.frames.has(index)) {
    const entry = api(`/api/frame/${index}`).then(async (view) => {
      const image = await loadImage(`/api/frame/${index}/bev.png?colour=${state.colouring}&token=${token}`);
      return { view, image };
    });
    state.frames.set(index, entry);
  }
  return state.frames.get(index);
}

function loadImage(src) {
  return new Promise((resolve, reject) => {
    const image = new Image();
    image.onload = () => resolve(image);
    image.onerror = () => reject(new Error(`cannot load ${src}`));
    image.src = src;
  });
}

function showProgress(progress) {
  const answered = progress.answered;
  $("progress").textContent =
    `${answered} of ${progress.asked} asked cells answered (${progress.skipped} can't tell), ` +
    `${progress.painted} painted; ${progress.labelled} labelled cells saved`;
  $("bar").max = Math.max(progress.asked, 1);
  $("bar").value = answered;
}

async function draw() {
  if (!state.current) return;
  const { view, image } = await frame(state.current.frame);
  const canvas = $("grid");
  const px = view.pixels_per_cell;
  const side = view.cells_per_side;
  canvas.width = canvas.height = side * px;
  const g = canvas.getContext("2d");
  g.drawImage(image, 0, 0);
  // Row 0 is the grid's south edge: drawn at the bottom, north up.
  const at = (cell) => [(cell % side) * px, (side - 1 - Math.floor(cell / side)) * px];
  for (let cell = 0; cell < side * side; cell++) {
    const call = view.calls[cell];
    if (call === ".") continue;
    const [x, y] = at(cell);
    g.fillStyle = call === "t" ? "rgba(47,127,216,0.18)" : "rgba(232,131,12,0.18)";
    g.fillRect(x, y, px, px);
  }
  for (const [k, answer] of state.answers) {
    const [f, cell] = k.split(":").map(Number);
    if (f !== state.current.frame) continue;
    const [x, y] = at(cell);
    if (answer === "skip") {
      g.strokeStyle = "#999";
      g.setLineDash([2, 2]);
      g.strokeRect(x + 1, y + 1, px - 2, px - 2);
      g.setLineDash([]);
    } else {
      g.fillStyle = answer === "traversable" ? "rgba(47,127,216,0.85)" : "rgba(232,131,12,0.85)";
      g.fillRect(x, y, px, px);
    }
  }
  for (const asked of state.asked) {
    if (asked.frame !== state.current.frame || state.answers.has(key(asked.frame, asked.cell))) continue;
    const [x, y] = at(asked.cell);
    g.strokeStyle = "#fff";
    g.lineWidth = 1.5;
    g.strokeRect(x + 0.5, y + 0.5, px - 1, px - 1);
  }
  const [x, y] = at(state.current.cell);
  g.lineWidth = 3;
  g.strokeStyle = "#000";
  g.strokeRect(x - 3, y - 3, px + 6, px + 6);
  g.strokeStyle = "#fff";
  g.strokeRect(x - 1, y - 1, px + 2, px + 2);
  g.lineWidth = 1;
  describe(view);
  drawCamera(view);
}

function describe(view) {
  const { frame: f, cell } = state.current;
  const side = view.cells_per_side;
  const index = state.askedIndex.get(key(f, cell));
  const call = { t: "traversable", n: "not traversable", ".": "no call (too few points)" }[view.calls[cell]];
  const answer = state.answers.get(key(f, cell));
  const asked = index === undefined ? "a cell not asked about" : `asked cell ${index + 1} of ${state.asked.length}`;
  const margin = index === undefined ? "" : `, margin ${state.asked[index].margin.toFixed(2)}`;
  $("asking").textContent =
    `${asked}: the model says ${call}${margin}` + (answer ? `; you said ${words[answer]}` : "");
  $("where").textContent =
    `${view.source}, frame ${view.frame}: row ${Math.floor(cell / side)}, column ${cell % side} ` +
    `(${view.cell_size_m} m cells, north up)`;
  $("skip").disabled = index === undefined;
}

async function drawCamera(view) {
  const figure = $("camera-figure");
  figure.hidden = !view.has_camera;
  if (!view.has_camera) return;
  const { frame: f, cell } = state.current;
  const [image, outline] = await Promise.all([
    loadImage(`/api/frame/${f}/camera.png?token=${token}`),
    api(`/api/frame/${f}/cell/${cell}/outline`),
  ]);
  const canvas = $("camera");
  canvas.width = image.width;
  canvas.height = image.height;
  const g = canvas.getContext("2d");
  g.drawImage(image, 0, 0);
  document.querySelector("#camera-figure figcaption").textContent = outline
    ? "The camera's view; the chosen cell outlined."
    : "The camera's view; the chosen cell lies outside it.";
  if (outline) {
    g.lineWidth = Math.max(3, image.width / 300);
    for (const colour of ["#000", "#fff"]) {
      g.strokeStyle = colour;
      g.beginPath();
      outline.forEach(([x, y], i) => (i ? g.lineTo(x, y) : g.moveTo(x, y)));
      g.closePath();
      g.stroke();
      g.lineWidth /= 2;
    }
  }
}

async function answer(value) {
  if (!state.current) return;
  const { frame: f, cell } = state.current;
  if (value === "skip" && !state.askedIndex.has(key(f, cell))) {
    say("only a cell asked about can be skipped");
    return;
  }
  try {
    const progress = await api("/api/answer", {
      method: "POST",
      headers: { "Content-Type": "application/json" },
      body: JSON.stringify({ frame: f, cell, answer: value }),
    });
    if (value === null) state.answers.delete(key(f, cell));
    else state.answers.set(key(f, cell), value);
    showProgress(progress);
    say("");
    if (value !== null && state.askedIndex.has(key(f, cell)) && !$("paint").checked) {
      await move(+1, true);
    } else {
      await draw();
    }
  } catch (error) {
    say(`not saved: ${error.message}`);
  }
}

// The next (or previous) asked cell from the current one; `unanswered` skips those
// answered.
async function move(step, unanswered) {
  const n = state.asked.length;
  if (!n) return;
  const from = state.current ? state.askedIndex.get(key(state.current.frame, state.current.cell)) : -1;
  let i = from === undefined ? -1 : from;
  for (let tries = 0; tries < n; tries++) {
    i = (i + step + n) % n;
    const asked = state.asked[i];
    if (!unanswered || !state.answers.has(key(asked.frame, asked.cell))) {
      state.current = { frame: asked.frame, cell: asked.cell };
      await draw();
      return;
    }
  }
  say("every asked cell is answered: paint more, or press Done");
  await draw();
}

async function clicked(event) {
  if (!state.current) return;
  const { view } = await frame(state.current.frame);
  const canvas = $("grid");
  const box = canvas.getBoundingClientRect();
  const px = view.pixels_per_cell;
  const side = view.cells_per_side;
  const col = Math.floor(((event.clientX - box.left) * canvas.width) / box.width / px);
  const rowFromTop = Math.floor(((event.clientY - box.top) * canvas.height) / box.height / px);
  if (col < 0 || col >= side || rowFromTop < 0 || rowFromTop >= side) return;
  const cell = (side - 1 - rowFromTop) * side + col;
  state.current = { frame: state.current.frame, cell };
  if ($("paint").checked) {
    if (view.calls[cell] === ".") {
      say("that cell holds too few points to learn from");
      await draw();
      return;
    }
    await answer($("brush").value || null);
  } else {
    await draw();
  }
}

function keyed(event) {
  if (event.target.tagName === "SELECT" || event.ctrlKey || event.metaKey || event.altKey) return;
  const actions = {
    t: () => answer("traversable"),
    n: () => answer("not_traversable"),
    s: () => answer("skip"),
    x: () => answer(null),
    ArrowRight: () => move(+1, true),
    " ": () => move(+1, true),
    ArrowLeft: () => move(-1, false),
    p: () => { $("paint").checked = !$("paint").checked; },
    h: () => {
      $("colouring").value = $("colouring").value === "height" ? "remission" : "height";
      recolour();
    },
  };
  const action = actions[event.key.length === 1 ? event.key.toLowerCase() : event.key];
  if (action) {
    event.preventDefault();
    action();
  }
}

function recolour() {
  state.colouring = $("colouring").value;
  state.frames.clear();
  draw();
}

async function start() {
  const session = await api("/api/session");
  state.session = session;
  state.asked = session.asked;
  session.asked.forEach((a, i) => state.askedIndex.set(key(a.frame, a.cell), i));
  for (const a of session.answers) state.answers.set(key(a.frame, a.cell), a.answer);
  showProgress(session.progress);
  $("traversable").onclick = () => answer("traversable");
  $("not-traversable").onclick = () => answer("not_traversable");
  $("skip").onclick = () => answer("skip");
  $("clear").onclick = () => answer(null);
  $("next").onclick = () => move(+1, true);
  $("previous").onclick = () => move(-1, false);
  $("colouring").onchange = recolour;
  $("grid").addEventListener("click", clicked);
  document.addEventListener("keydown", keyed);
  $("done").onclick = async () => {
    const progress = await api("/api/done", { method: "POST" });
    showProgress(progress);
    say("Done: the server has stopped, and every answer is in the labels file. You may close this page.");
    document.body.classList.add("finished");
  };
  if (!state.asked.length) {
    say("the model is sure of every cell of these frames: nothing to ask");
    return;
  }
  await move(+1, true);
}

start().catch((error) => say(`cannot start: ${error.message}`));
