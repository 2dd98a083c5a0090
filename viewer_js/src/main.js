// cassi_fit's one-file recording viewer: wires the page written by cassi_fit.viewer._page
// (its elements, its JSON data block) to the 3D view, the midsagittal section, the sound,
// the label timeline and the plots. One clock: the sound's when the page has sound (its
// currentTime is the recording's time), else the page's own.
import { Motion, frameAt, readData } from "./data.js";
import { drawPlot, buildTimeline } from "./panels.js";
import { FaceScene } from "./scene.js";
import { Section } from "./section.js";

const $ = (id) => document.getElementById(id);

class Viewer {
  constructor(data) {
    this.data = data;
    this.times = data.times;
    this.n = this.times.length;
    this.motion = new Motion(data.mesh, data.motion);
    this.frame = 0;
    this.playing = false;
    this.speed = 1;
    this.audio = $("cassi-audio");
    this.audioTime = null; // the sound's time as last seen or set here
    this.section = new Section($("cassi-section"), data);
    this.scene = this._makeScene();
    this.preset = "side";
    this._wire();
    this.plots = [
      ["cassi-plot-jaw", data.plots.jaw_deg, "jaw opening (deg)"],
      ["cassi-plot-lips", data.plots.lip_aperture_mm, "lip aperture (mm)"],
    ];
    this.labels = buildTimeline($("cassi-timeline"), data, (t) => this.seekTime(t));
    this.resize();
    this.setPreset("side");
    this.show(0);
    requestAnimationFrame(() => this._tick());
  }

  _makeScene() {
    const canvas = $("cassi-3d");
    let probe = null;
    try {
      probe = document.createElement("canvas").getContext("webgl2");
    } catch (err) {
      probe = null;
    }
    if (!probe) return this._noWebGL("this browser gives the page no WebGL");
    try {
      return new FaceScene(canvas, this.data, this.data.views.background);
    } catch (err) {
      return this._noWebGL(`WebGL failed to start (${err.message})`);
    }
  }

  _noWebGL(why) {
    $("cassi-3d").style.display = "none";
    const note = $("cassi-nogl");
    note.textContent =
      `The 3D view cannot be drawn: ${why}. The midsagittal section, the sound, ` +
      "the labels and the plots still work; open the page in a browser with WebGL " +
      "(Chromium, Firefox) to see the face.";
    note.style.display = "block";
    return null;
  }

  _wire() {
    $("cassi-play").onclick = () => (this.playing ? this.pause() : this.play());
    $("cassi-back").onclick = () => this.step(-1);
    $("cassi-fwd").onclick = () => this.step(1);
    const scrub = $("cassi-scrub");
    scrub.max = String(this.n - 1);
    scrub.oninput = () => this.seekFrame(Number(scrub.value));
    $("cassi-speed").onchange = (e) => this.setSpeed(Number(e.target.value));
    for (const b of document.querySelectorAll("[data-preset]")) {
      b.onclick = () => this.setPreset(b.dataset.preset);
    }
    $("cassi-skin").onchange = (e) => this.setSkin(e.target.value);
    for (const box of document.querySelectorAll("[data-part]")) {
      box.onchange = () => {
        if (this.scene) this.scene.setPart(box.dataset.part, box.checked);
        this.section.hidden = new Set(
          [...document.querySelectorAll("[data-part]")]
            .filter((b) => !b.checked)
            .map((b) => b.dataset.part),
        );
        this.show(this.frame);
      };
    }
    for (const box of document.querySelectorAll("[data-pellets]")) {
      box.onchange = () => {
        const which = box.dataset.pellets;
        if (this.scene) this.scene.setPellets(which, box.checked);
        this.section[which === "measured" ? "showMeasured" : "showModel"] = box.checked;
        this.show(this.frame);
      };
    }
    for (const id of ["cassi-plot-jaw", "cassi-plot-lips"]) {
      $(id).onclick = (e) => {
        const r = e.target.getBoundingClientRect();
        const t0 = this.times[0];
        const t1 = this.times[this.n - 1];
        this.seekTime(t0 + ((e.clientX - r.left) / r.width) * (t1 - t0));
      };
    }
    window.addEventListener("resize", () => this.resize());
    document.addEventListener("keydown", (e) => {
      if (e.target.tagName === "SELECT" || e.target.tagName === "INPUT") return;
      if (e.key === "ArrowLeft") this.step(-1);
      else if (e.key === "ArrowRight") this.step(1);
      else if (e.key === " ") {
        e.preventDefault();
        this.playing ? this.pause() : this.play();
      } else return;
    });
    if (this.audio) {
      this.audio.preservesPitch = false; // slowed sound is slowed, as a tape would be
      this.audio.addEventListener("seeking", () => this._followAudio());
      this.audio.addEventListener("ended", () => this.pause());
    }
  }

  resize() {
    const c3 = $("cassi-3d");
    if (this.scene) {
      this.scene.resize(c3.clientWidth, c3.clientHeight);
      this.scene.setPreset(this.preset);
    }
    const sc = $("cassi-section");
    sc.width = sc.clientWidth;
    sc.height = sc.clientHeight;
    for (const [id] of this.plots) {
      const c = $(id);
      c.width = c.clientWidth;
      c.height = c.clientHeight;
    }
    this.show(this.frame);
  }

  // --- the clock ------------------------------------------------------------------
  get time() {
    return this.times[this.frame];
  }

  play() {
    if (this.frame >= this.n - 1) this.seekFrame(0);
    this.playing = true;
    $("cassi-play").textContent = "pause";
    if (this.audio) {
      this.audio.playbackRate = this.speed;
      this.audio.currentTime = this.time;
      this.audioTime = this.time;
      this.audio.play().catch(() => this._ownClock());
    } else this._ownClock();
  }

  _ownClock() {
    this.clockStart = performance.now();
    this.clockTime = this.time;
    this.ownClock = true;
  }

  pause() {
    this.playing = false;
    this.ownClock = false;
    $("cassi-play").textContent = "play";
    if (this.audio && !this.audio.paused) this.audio.pause();
  }

  setSpeed(speed) {
    this.speed = speed;
    if (this.audio) this.audio.playbackRate = speed;
    if (this.ownClock) this._ownClock();
    $("cassi-speed").value = String(speed);
  }

  // The sound's time was set (by a seek elsewhere, or a script): show its frame.
  _followAudio() {
    const t = this.audio.currentTime;
    if (t === this.audioTime) return;
    this.audioTime = t;
    this.show(frameAt(this.times, t));
  }

  _tick() {
    if (this.playing) {
      let t;
      if (this.ownClock) {
        t = this.clockTime + ((performance.now() - this.clockStart) / 1000) * this.speed;
      } else {
        t = this.audio.currentTime;
        this.audioTime = t;
      }
      this.show(frameAt(this.times, t));
      if (this.ownClock && t >= this.times[this.n - 1]) this.pause();
    } else if (this.audio && this.audio.currentTime !== this.audioTime) {
      this._followAudio();
    }
    requestAnimationFrame(() => this._tick());
  }

  seekFrame(f) {
    f = Math.max(0, Math.min(this.n - 1, Math.round(f)));
    if (this.audio) {
      this.audio.currentTime = this.times[f];
      this.audioTime = this.audio.currentTime;
    }
    if (this.ownClock) {
      this.clockStart = performance.now();
      this.clockTime = this.times[f];
    }
    this.show(f);
  }

  seekTime(t) {
    // a label's start: the first frame at or after it
    let f = frameAt(this.times, t);
    if (this.times[f] < t - 1e-9 && f < this.n - 1) f += 1;
    this.seekFrame(f);
  }

  step(delta) {
    this.pause();
    this.seekFrame(this.frame + delta);
  }

  // --- drawing --------------------------------------------------------------------
  show(f) {
    this.frame = f;
    const vertices = this.motion.frame(f);
    const t = this.times[f];
    if (this.scene) {
      this.scene.setFrame(vertices, f);
      this.scene.draw();
    }
    this.section.draw(vertices, f, t);
    $("cassi-scrub").value = String(f);
    const line = this.data.frame_index[f] + 1;
    const label = this.labels ? this.labels.at(t) : "";
    $("cassi-clock").textContent =
      `t = ${t.toFixed(3)} s   line ${line}   frame ${f + 1}/${this.n}` +
      (label ? `   "${label}"` : "");
    for (const [id, values, title] of this.plots || []) {
      drawPlot($(id), this.times, values, f, title);
    }
    if (this.labels) this.labels.mark(t);
  }

  setPreset(name) {
    this.preset = name;
    const skin = { front: "solid", side: "solid", inside: "cut", top: "hidden" }[name];
    this.setSkin(skin);
    for (const b of document.querySelectorAll("[data-preset]")) {
      b.classList.toggle("on", b.dataset.preset === name);
    }
    if (this.scene) this.scene.setPreset(name);
  }

  setSkin(mode) {
    $("cassi-skin").value = mode;
    if (this.scene) {
      this.scene.setSkin(mode);
      this.scene.draw();
    }
  }
}

function start() {
  try {
    window.cassiViewer = new Viewer(readData("cassi-data"));
  } catch (err) {
    const note = $("cassi-nogl");
    note.textContent = `The viewer could not start: ${err.message}`;
    note.style.display = "block";
    throw err;
  }
}

if (document.readyState === "loading") document.addEventListener("DOMContentLoaded", start);
else start();
