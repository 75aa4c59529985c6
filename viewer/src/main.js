// The browser side of tether_gym.viewer: one page for the live view, recorded episodes and the
// self-contained export. It reads its episodes either from the page itself (an export, or a
// recording served by `tether-gym-view --recording`) or, in live mode, from the server's
// /api/meta and /api/frames, and draws them with three.js. Bundled by scripts/build_viewer.sh
// into tether_gym/viewer/static/viewer.js; the Python side fills in the page template.
//
// Positions are drawn in each cluster's centre-of-mass frame, with every node's displacement
// from its nominal place multiplied by the exaggeration: the default ids vibrate by centimetres
// on 100 m cables.

import {
  AmbientLight,
  ArrowHelper,
  AxesHelper,
  BufferAttribute,
  BufferGeometry,
  Color,
  DirectionalLight,
  LineBasicMaterial,
  LineDashedMaterial,
  LineSegments,
  Mesh,
  MeshLambertMaterial,
  OctahedronGeometry,
  PerspectiveCamera,
  Scene,
  SphereGeometry,
  Vector3,
  WebGLRenderer,
} from "three";
import { OrbitControls } from "three/examples/jsm/controls/OrbitControls.js";

const BACKGROUND = 0xf6f7f9;
const ROLE_COLOURS = { thruster: 0x1f3b73, passive: 0xe8e8e8, bead: 0x8a8a8a };
const ROLE_NAMES = { thruster: "satellite with thrusters", passive: "passive satellite", bead: "tether bead" };
const SLACK_COLOUR = 0xff8c00;
const BROKEN_COLOUR = 0x555555;
const THRUST_COLOUR = 0xd62728;
// Tension colours: from a pale blue at zero tension to a dark red at the scale's top.
const TENSION_LOW = new Color(0x6baed6);
const TENSION_MID = new Color(0x3b4cc0);
const TENSION_HIGH = new Color(0xb2182b);
const EPISODE_COLOURS = ["#1f77b4", "#d62728", "#2ca02c", "#9467bd"];
const SPEEDS = [0.1, 0.25, 0.5, 1, 2, 4, 8, 16];

// ---------------------------------------------------------------- data

function decode(encoded, dtype) {
  const binary = atob(encoded);
  const bytes = new Uint8Array(binary.length);
  for (let i = 0; i < binary.length; i++) bytes[i] = binary.charCodeAt(i);
  if (dtype === "f8") return new Float64Array(bytes.buffer);
  if (dtype === "u1") return bytes;
  throw new Error(`unknown dtype ${dtype}`);
}

// A typed array that grows as live frames arrive, `width` values per frame.
class Frames {
  constructor(Type, width) {
    this.Type = Type;
    this.width = width;
    this.data = new Type(Math.max(width, 1) * 64);
    this.count = 0;
  }
  append(values, count) {
    const needed = (this.count + count) * this.width;
    if (needed > this.data.length) {
      const grown = new this.Type(Math.max(needed, 2 * this.data.length));
      grown.set(this.data.subarray(0, this.count * this.width));
      this.data = grown;
    }
    this.data.set(values.subarray(0, count * this.width), this.count * this.width);
    this.count += count;
  }
  frame(k) {
    return this.data.subarray(k * this.width, (k + 1) * this.width);
  }
  value(k) {
    return this.data[k];
  }
}

const FIELDS = {
  time: ["f8", (m) => 1],
  positions: ["f8", (m) => 3 * m.num_nodes],
  tension: ["f8", (m) => m.cables.length],
  slack: ["u1", (m) => m.cables.length],
  broken: ["u1", (m) => m.cables.length],
  thrust: ["f8", (m) => 3 * m.num_nodes],
  reward: ["f8", (m) => 1],
  energy: ["f8", (m) => 1],
};

class Episode {
  constructor(meta) {
    this.meta = meta;
    this.frames = {};
    for (const [name, [dtype, width]] of Object.entries(FIELDS)) {
      this.frames[name] = new Frames(dtype === "f8" ? Float64Array : Uint8Array, width(meta));
    }
    this.done = false;
    this.tensionScale = 0;
  }
  get count() {
    return this.frames.time.count;
  }
  append(chunk) {
    const count = chunk.count;
    for (const [name, [dtype]] of Object.entries(FIELDS)) {
      this.frames[name].append(decode(chunk.frames[name], dtype), count);
    }
    const tension = this.frames.tension;
    for (let i = (tension.count - count) * tension.width; i < tension.count * tension.width; i++) {
      if (Number.isFinite(tension.data[i]) && tension.data[i] > this.tensionScale) this.tensionScale = tension.data[i];
    }
    if (chunk.done) {
      this.done = true;
      this.meta.end_reason = chunk.end_reason;
      this.meta.return = chunk.return;
    }
  }
}

// ---------------------------------------------------------------- one cluster's scene

function tensionColour(fraction, target) {
  const f = Math.min(Math.max(fraction, 0), 1);
  if (f < 0.5) return target.copy(TENSION_LOW).lerp(TENSION_MID, 2 * f);
  return target.copy(TENSION_MID).lerp(TENSION_HIGH, 2 * f - 1);
}

function lineSet(material, count) {
  const geometry = new BufferGeometry();
  geometry.setAttribute("position", new BufferAttribute(new Float32Array(6 * count), 3));
  geometry.setAttribute("color", new BufferAttribute(new Float32Array(6 * count), 3));
  const lines = new LineSegments(geometry, material);
  lines.frustumCulled = false; // its points move every frame: no bounding sphere to keep current
  return lines;
}

class ClusterView {
  constructor(meta) {
    this.meta = meta;
    const n = meta.num_nodes;
    this.scene = new Scene();
    this.scene.background = new Color(BACKGROUND);
    this.scene.add(new AmbientLight(0xffffff, 1.6));
    const light = new DirectionalLight(0xffffff, 1.8);
    light.position.set(1, -1, 2);
    this.scene.add(light);
    this.nominal = Float64Array.from(meta.nominal);
    centre(this.nominal, n);
    let span = 0;
    for (let i = 0; i < n; i++) {
      span = Math.max(span, Math.hypot(this.nominal[3 * i], this.nominal[3 * i + 1], this.nominal[3 * i + 2]));
    }
    this.span = Math.max(span, 1e-3);
    this.scene.add(new AxesHelper(0.25 * this.span));
    this.nodes = [];
    const satelliteGeometry = new SphereGeometry(0.045 * this.span, 24, 16);
    const beadGeometry = new SphereGeometry(0.014 * this.span, 10, 8);
    for (let i = 0; i < n; i++) {
      const role = meta.roles[i];
      const mesh = new Mesh(
        role === "bead" ? beadGeometry : satelliteGeometry,
        new MeshLambertMaterial({ color: ROLE_COLOURS[role] }),
      );
      this.scene.add(mesh);
      this.nodes.push(mesh);
    }
    const m = meta.cables.length;
    this.taut = lineSet(new LineBasicMaterial({ vertexColors: true }), m);
    this.slack = lineSet(new LineDashedMaterial({ color: SLACK_COLOUR, dashSize: 0.04 * this.span, gapSize: 0.03 * this.span }), m);
    this.broken = lineSet(new LineDashedMaterial({ color: BROKEN_COLOUR, dashSize: 0.01 * this.span, gapSize: 0.02 * this.span }), m);
    for (const set of [this.taut, this.slack, this.broken]) this.scene.add(set);
    this.breaks = [];
    const breakGeometry = new OctahedronGeometry(0.03 * this.span);
    for (let c = 0; c < m; c++) {
      const mark = new Mesh(breakGeometry, new MeshLambertMaterial({ color: THRUST_COLOUR }));
      mark.visible = false;
      this.scene.add(mark);
      this.breaks.push(mark);
    }
    this.arrows = [];
    for (const node of meta.thrusters) {
      const arrow = new ArrowHelper(new Vector3(1, 0, 0), new Vector3(), 1, THRUST_COLOUR);
      arrow.visible = false;
      this.scene.add(arrow);
      this.arrows.push([node, arrow]);
    }
    this.shown = new Float64Array(3 * n);
    this.colour = new Color();
  }

  // Places everything as at frame `k` (fractional k interpolates positions between frames).
  update(episode, k, exaggeration) {
    const meta = this.meta;
    const n = meta.num_nodes;
    const last = episode.count - 1;
    const k0 = Math.min(Math.floor(k), last);
    const k1 = Math.min(k0 + 1, last);
    const w = Math.min(Math.max(k - k0, 0), 1);
    const p0 = episode.frames.positions.frame(k0);
    const p1 = episode.frames.positions.frame(k1);
    const shown = this.shown;
    for (let j = 0; j < 3 * n; j++) shown[j] = (1 - w) * p0[j] + w * p1[j];
    centre(shown, n);
    for (let j = 0; j < 3 * n; j++) shown[j] = this.nominal[j] + exaggeration * (shown[j] - this.nominal[j]);
    for (let i = 0; i < n; i++) this.nodes[i].position.set(shown[3 * i], shown[3 * i + 1], shown[3 * i + 2]);

    const tension = episode.frames.tension.frame(k0);
    const slack = episode.frames.slack.frame(k0);
    const broken = episode.frames.broken.frame(k0);
    const scale = episode.tensionScale > 0 ? episode.tensionScale : 1;
    const sets = { taut: this.taut.geometry, slack: this.slack.geometry, broken: this.broken.geometry };
    const cables = meta.cables;
    for (let c = 0; c < cables.length; c++) {
      const [a, b] = cables[c];
      const kind = broken[c] ? "broken" : slack[c] ? "slack" : "taut";
      for (const [name, geometry] of Object.entries(sets)) {
        const position = geometry.attributes.position.array;
        const to = name === kind ? b : a; // a cable drawn by another set collapses to a point here
        for (let d = 0; d < 3; d++) {
          position[6 * c + d] = shown[3 * a + d];
          position[6 * c + 3 + d] = shown[3 * to + d];
        }
      }
      if (kind === "taut") {
        tensionColour(tension[c] / scale, this.colour);
        const colour = sets.taut.attributes.color.array;
        for (let end = 0; end < 2; end++) {
          colour[6 * c + 3 * end] = this.colour.r;
          colour[6 * c + 3 * end + 1] = this.colour.g;
          colour[6 * c + 3 * end + 2] = this.colour.b;
        }
      }
      const mark = this.breaks[c];
      mark.visible = kind === "broken";
      if (mark.visible) {
        mark.position.set(
          0.5 * (shown[3 * a] + shown[3 * b]),
          0.5 * (shown[3 * a + 1] + shown[3 * b + 1]),
          0.5 * (shown[3 * a + 2] + shown[3 * b + 2]),
        );
      }
    }
    for (const set of [this.taut, this.slack, this.broken]) {
      set.geometry.attributes.position.needsUpdate = true;
      set.geometry.attributes.color.needsUpdate = true;
    }
    this.slack.computeLineDistances();
    this.broken.computeLineDistances();

    const thrust = episode.frames.thrust.frame(k0);
    const arrowScale = (0.35 * this.span) / Math.max(meta.max_thrust, 1e-12);
    for (const [node, arrow] of this.arrows) {
      const f = new Vector3(thrust[3 * node], thrust[3 * node + 1], thrust[3 * node + 2]);
      const length = f.length() * arrowScale;
      arrow.visible = length > 1e-6 * this.span;
      if (!arrow.visible) continue;
      arrow.position.set(shown[3 * node], shown[3 * node + 1], shown[3 * node + 2]);
      arrow.setDirection(f.normalize());
      arrow.setLength(length, Math.min(0.3 * length, 0.08 * this.span), Math.min(0.15 * length, 0.04 * this.span));
    }
    let slackCount = 0;
    let brokenCount = 0;
    for (let c = 0; c < cables.length; c++) {
      if (broken[c]) brokenCount++;
      else if (slack[c]) slackCount++;
    }
    return { slack: slackCount, broken: brokenCount };
  }
}

function centre(values, n) {
  const mean = [0, 0, 0];
  for (let i = 0; i < n; i++) for (let d = 0; d < 3; d++) mean[d] += values[3 * i + d] / n;
  for (let i = 0; i < n; i++) for (let d = 0; d < 3; d++) values[3 * i + d] -= mean[d];
}

function frameName(frame) {
  if (frame.kind === "hill") {
    return `Hill frame: x radial, y along-track, z orbit normal; orbit rate ${frame.rate.toPrecision(3)} rad/s`;
  }
  if (frame.kind === "rotating") return `rotating frame: spin ${frame.rate.toPrecision(3)} rad/s about z`;
  return "free space (inertial frame)";
}

// ---------------------------------------------------------------- plots

class Plot {
  constructor(canvas, label, field, logarithmic) {
    this.canvas = canvas;
    this.label = label;
    this.field = field;
    this.logarithmic = logarithmic;
  }
  draw(episodes, time, duration) {
    const canvas = this.canvas;
    const ratio = window.devicePixelRatio || 1;
    const width = canvas.clientWidth;
    const height = canvas.clientHeight;
    if (canvas.width !== Math.round(width * ratio)) canvas.width = Math.round(width * ratio);
    if (canvas.height !== Math.round(height * ratio)) canvas.height = Math.round(height * ratio);
    const g = canvas.getContext("2d");
    g.setTransform(ratio, 0, 0, ratio, 0, 0);
    g.clearRect(0, 0, width, height);
    const left = 46;
    const right = 8;
    const top = 16;
    const bottom = 18;
    const transform = (v) => (this.logarithmic ? Math.log10(Math.max(v, 1e-300)) : v);
    let low = Infinity;
    let high = -Infinity;
    for (const episode of episodes) {
      const values = episode.frames[this.field];
      for (let k = 0; k < values.count; k++) {
        const v = values.value(k);
        if (!Number.isFinite(v) || (this.logarithmic && v <= 0)) continue;
        low = Math.min(low, transform(v));
        high = Math.max(high, transform(v));
      }
    }
    g.font = "11px sans-serif";
    g.fillStyle = "#333";
    g.fillText(this.label, left, 11);
    if (!Number.isFinite(low)) return;
    if (high - low < 1e-12) {
      high += 0.5;
      low -= 0.5;
    }
    const x = (t) => left + ((width - left - right) * t) / duration;
    const y = (v) => top + ((height - top - bottom) * (high - transform(v))) / (high - low);
    g.strokeStyle = "#bbb";
    g.strokeRect(left, top, width - left - right, height - top - bottom);
    g.fillStyle = "#555";
    const tick = (v) => (this.logarithmic ? `1e${v.toFixed(1)}` : v.toPrecision(3));
    g.fillText(tick(high), 2, top + 8);
    g.fillText(tick(low), 2, height - bottom);
    g.fillText("0 s", left, height - 4);
    g.fillText(`${duration.toFixed(0)} s`, width - right - 26, height - 4);
    episodes.forEach((episode, index) => {
      const values = episode.frames[this.field];
      const times = episode.frames.time;
      g.strokeStyle = EPISODE_COLOURS[index % EPISODE_COLOURS.length];
      g.lineWidth = 1.2;
      g.beginPath();
      let drawing = false;
      for (let k = 0; k < values.count; k++) {
        const v = values.value(k);
        if (!Number.isFinite(v) || (this.logarithmic && v <= 0)) {
          drawing = false;
          continue;
        }
        if (drawing) g.lineTo(x(times.value(k)), y(v));
        else g.moveTo(x(times.value(k)), y(v));
        drawing = true;
      }
      g.stroke();
    });
    g.strokeStyle = "#000";
    g.lineWidth = 1;
    g.beginPath();
    g.moveTo(x(time), top);
    g.lineTo(x(time), height - bottom);
    g.stroke();
  }
}

// ---------------------------------------------------------------- the page

function element(id) {
  return document.getElementById(id);
}

class Viewer {
  constructor(config) {
    this.config = config;
    this.live = config.mode === "live";
    this.episodes = [];
    this.views = [];
    this.playing = this.live || config.autoplay === true;
    this.speed = 1;
    this.k = 0; // fractional frame index
    this.exaggeration = config.exaggeration || 100;
    this.frameTimes = [];
    this.fps = 0;
    this.lastWall = null;
    this.fetching = false;
    this.liveError = null;
  }

  async start() {
    const meta = this.live ? await (await fetch("api/meta")).json() : this.config;
    for (const item of meta.episodes) {
      const episode = new Episode(item.meta);
      if (item.frames) episode.append(item);
      this.episodes.push(episode);
    }
    if (this.live) await this.poll();
    this.build();
    this.bind();
    requestAnimationFrame((wall) => this.tick(wall));
  }

  get interval() {
    return this.episodes[0].meta.control_interval;
  }

  get available() {
    return Math.min(...this.episodes.map((e) => e.count));
  }

  get duration() {
    const meta = this.episodes[0].meta;
    return Math.max(meta.max_steps * meta.control_interval, (this.available - 1) * meta.control_interval);
  }

  build() {
    const canvas = element("scene");
    this.renderer = new WebGLRenderer({ canvas, antialias: true, preserveDrawingBuffer: true });
    this.renderer.setPixelRatio(window.devicePixelRatio || 1);
    this.renderer.setScissorTest(true);
    this.views = this.episodes.map((episode) => new ClusterView(episode.meta));
    const span = Math.max(...this.views.map((v) => v.span));
    this.camera = new PerspectiveCamera(40, 1, 0.01 * span, 100 * span);
    this.camera.up.set(0, 0, 1);
    this.camera.position.set(2.6 * span, -3.4 * span, 2.2 * span);
    this.controls = new OrbitControls(this.camera, canvas);
    this.controls.target.set(0, 0, 0);
    this.controls.update();
    this.plots = [
      new Plot(element("energy"), "vibration energy (J, log scale)", "energy", true),
      new Plot(element("reward"), "reward per step", "reward", false),
    ];
    const titles = element("titles");
    titles.innerHTML = "";
    this.episodes.forEach((episode, index) => {
      const meta = episode.meta;
      const div = document.createElement("div");
      div.className = "episode-title";
      div.style.borderColor = EPISODE_COLOURS[index % EPISODE_COLOURS.length];
      div.textContent = `${meta.controller} on ${meta.env_id}, seed ${meta.seed}`;
      titles.appendChild(div);
    });
    element("frame-name").textContent = frameName(this.episodes[0].meta.frame);
    const roles = new Set(this.episodes.flatMap((e) => e.meta.roles));
    element("legend-roles").innerHTML = [...roles]
      .map((role) => {
        const colour = `#${ROLE_COLOURS[role].toString(16).padStart(6, "0")}`;
        return `<span class="swatch round" style="background:${colour}"></span>${ROLE_NAMES[role]}`;
      })
      .join("<br>");
    this.resize();
  }

  bind() {
    const slider = element("time-slider");
    slider.addEventListener("input", () => {
      this.k = Number(slider.value);
      this.render();
    });
    element("play").addEventListener("click", () => this.setPlaying(!this.playing));
    element("step-back").addEventListener("click", () => this.step(-1));
    element("step-forward").addEventListener("click", () => this.step(1));
    const speed = element("speed");
    speed.innerHTML = SPEEDS.map((s) => `<option value="${s}"${s === 1 ? " selected" : ""}>${s}x</option>`).join("");
    speed.addEventListener("change", () => {
      this.speed = Number(speed.value);
    });
    const exaggeration = element("exaggeration");
    exaggeration.value = String(Math.log10(this.exaggeration));
    exaggeration.addEventListener("input", () => {
      this.exaggeration = 10 ** Number(exaggeration.value);
      this.render();
    });
    if (this.live) {
      const next = element("next-episode");
      next.hidden = false;
      next.addEventListener("click", async () => {
        await fetch("api/next", { method: "POST" });
        window.location.reload();
      });
    }
    for (const plot of ["energy", "reward"]) {
      element(plot).addEventListener("click", (event) => {
        const rect = event.target.getBoundingClientRect();
        const fraction = (event.clientX - rect.left - 46) / (rect.width - 54);
        this.k = Math.max(0, Math.min(this.available - 1, Math.round((fraction * this.duration) / this.interval)));
        this.render();
      });
    }
    window.addEventListener("resize", () => this.resize());
    window.addEventListener("keydown", (event) => {
      if (event.target instanceof HTMLInputElement || event.target instanceof HTMLSelectElement) return;
      if (event.key === " ") this.setPlaying(!this.playing);
      else if (event.key === "ArrowRight") this.step(1);
      else if (event.key === "ArrowLeft") this.step(-1);
      else return;
      event.preventDefault();
    });
    this.controls.addEventListener("change", () => this.render());
  }

  setPlaying(playing) {
    this.playing = playing;
    if (playing && !this.live && this.k >= this.available - 1) this.k = 0;
    element("play").textContent = playing ? "Pause" : "Play";
  }

  step(direction) {
    this.setPlaying(false);
    this.k = Math.max(0, Math.min(this.available - 1, Math.round(this.k) + direction));
    this.render();
  }

  resize() {
    const canvas = element("scene");
    this.renderer.setSize(canvas.clientWidth, canvas.clientHeight, false);
    this.render();
  }

  async poll() {
    // Asks for the frames after those held, and tells the server how far the clock has got, so
    // that it simulates ahead of the view and no further.
    if (this.fetching) return;
    this.fetching = true;
    try {
      const from = this.available;
      const want = Math.ceil(this.k) + Math.ceil((2 * this.speed) / this.interval) + 1;
      const reply = await (await fetch(`api/frames?from=${from}&want=${want}`)).json();
      if (reply.error) throw new Error(reply.error);
      reply.episodes.forEach((chunk, index) => {
        if (chunk.count > 0 || chunk.done) this.episodes[index].append(chunk);
      });
      this.simulationRate = reply.steps_per_second;
    } catch (error) {
      if (!this.liveError) console.warn(`live view: ${error}`);
      this.liveError = String(error);
    } finally {
      this.fetching = false;
    }
  }

  tick(wall) {
    if (this.lastWall !== null) {
      const seconds = (wall - this.lastWall) / 1000;
      this.frameTimes.push(wall);
      while (this.frameTimes.length > 0 && wall - this.frameTimes[0] > 1000) this.frameTimes.shift();
      this.fps = this.frameTimes.length;
      if (this.playing) {
        this.k += (Math.min(seconds, 0.25) * this.speed) / this.interval;
        const last = this.available - 1;
        if (this.k >= last) {
          this.k = last;
          // A live episode still running waits at its newest frame for the next ones.
          if (!this.live || this.episodes.every((e) => e.done)) this.setPlaying(false);
        }
      }
    }
    this.lastWall = wall;
    if (this.live && !this.episodes.every((e) => e.done)) this.poll();
    this.render();
    requestAnimationFrame((next) => this.tick(next));
  }

  render() {
    if (!this.renderer) return;
    const canvas = element("scene");
    const width = canvas.clientWidth;
    const height = canvas.clientHeight;
    const panels = this.views.length;
    const panelWidth = width / panels;
    this.camera.aspect = panelWidth / Math.max(height, 1);
    this.camera.updateProjectionMatrix();
    const k = Math.max(0, Math.min(this.k, this.available - 1));
    const counts = [];
    this.views.forEach((view, index) => {
      counts.push(view.update(this.episodes[index], k, this.exaggeration));
      const left = Math.round(index * panelWidth);
      this.renderer.setViewport(left, 0, Math.round(panelWidth), height);
      this.renderer.setScissor(left, 0, Math.round(panelWidth), height);
      this.renderer.render(view.scene, this.camera);
    });
    const frame = Math.round(k);
    const time = this.episodes[0].frames.time.value(Math.floor(k)) + (k - Math.floor(k)) * this.interval;
    const slider = element("time-slider");
    slider.max = String(Math.max(this.available - 1, 0));
    if (document.activeElement !== slider) slider.value = String(frame);
    element("time").textContent = `t = ${time.toFixed(1)} s  (step ${frame} of ${this.available - 1})`;
    element("status").innerHTML = this.episodes
      .map((episode, index) => {
        const c = counts[index];
        const energy = episode.frames.energy.value(Math.floor(k));
        const atEnd = episode.done && Math.floor(k) >= episode.count - 1;
        const total = typeof episode.meta.return === "number" ? episode.meta.return.toFixed(2) : "n/a";
        const end = atEnd ? `; ended (${episode.meta.end_reason}), return ${total}` : "";
        const colour = EPISODE_COLOURS[index % EPISODE_COLOURS.length];
        return (
          `<span style="color:${colour}">&#9632;</span> energy ${energy.toExponential(2)} J, ` +
          `slack ${c.slack}, broken ${c.broken}${end}`
        );
      })
      .join("<br>");
    const scale = Math.max(...this.episodes.map((e) => e.tensionScale));
    element("tension-scale").textContent = `${scale.toPrecision(3)} N`;
    element("exaggeration-value").textContent = `x${this.exaggeration.toPrecision(3)}`;
    let rate = `${this.fps} fps`;
    if (this.live && this.simulationRate) {
      rate += `; simulation ${this.simulationRate.toFixed(0)} steps/s (${(this.simulationRate * this.interval).toFixed(1)}x real time)`;
    }
    element("rate").textContent = rate;
    for (const plot of this.plots) plot.draw(this.episodes, time, this.duration);
  }
}

// Test and scripting hooks: what the page shows, read back by the browser tests.
function hooks(viewer) {
  return {
    viewer,
    ready: false,
    frames: () => viewer.available,
    frame: () => viewer.k,
    fps: () => viewer.fps,
    setFrame: (k) => {
      viewer.setPlaying(false);
      viewer.k = k;
      viewer.render();
    },
    recordedPositions: (panel, k) => Array.from(viewer.episodes[panel].frames.positions.frame(k)),
    shownPositions: (panel) => viewer.views[panel].nodes.map((node) => node.position.toArray()),
  };
}

async function main() {
  const data = JSON.parse(element("tether-view-data").textContent);
  const viewer = new Viewer(data);
  window.tetherViewer = hooks(viewer);
  try {
    await viewer.start();
    window.tetherViewer.ready = true;
  } catch (error) {
    element("status").textContent = `could not start the view: ${error}`;
    throw error;
  }
}

main();
