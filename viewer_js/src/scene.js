// The 3D view: one three.js mesh per part of the face model (sharing one position buffer),
// the measured pellets with their trails and the model's pellet sites, an orthographic
// camera with the paper's four views as presets (fitted as cassi_fit.render fits them) and
// orbit/zoom controls.
//
// The model frame is left-handed (x front, y up, z the subject's left); the scene's root
// reflects z, so that three.js's right-handed world shows the subject as a camera would.
import {
  AmbientLight,
  BufferAttribute,
  BufferGeometry,
  Color,
  DirectionalLight,
  DoubleSide,
  Group,
  Line,
  LineBasicMaterial,
  Mesh,
  MeshBasicMaterial,
  MeshLambertMaterial,
  OrthographicCamera,
  Plane,
  Scene,
  SphereGeometry,
  Vector3,
  WebGLRenderer,
} from "three";
import { OrbitControls } from "three/examples/jsm/controls/OrbitControls.js";

const CUT_PARTS = new Set(["skin", "teeth", "palate"]); // the inside view's near half cut away
export const SKIN_MODES = ["solid", "see-through", "cut", "hidden"];

function toWorld(p) {
  return new Vector3(p[0], p[1], -p[2]);
}

// The skin's hair as the toolkit's renderer draws it: the hair's share of the colour
// interpolated across each triangle and clipped per pixel (a sharp edge along a line,
// not along the triangles).
function withHair(geometry, material, mesh) {
  geometry.setAttribute("hair", new BufferAttribute(mesh.hair, 1));
  const colour = new Color().setRGB(...mesh.hair_colour, "srgb");
  material.onBeforeCompile = (shader) => {
    shader.uniforms.hairColour = { value: colour };
    shader.vertexShader = shader.vertexShader
      .replace("#include <common>", "#include <common>\nattribute float hair;\nvarying float vHair;")
      .replace("#include <begin_vertex>", "#include <begin_vertex>\nvHair = hair;");
    shader.fragmentShader = shader.fragmentShader
      .replace("#include <common>", "#include <common>\nvarying float vHair;\nuniform vec3 hairColour;")
      .replace(
        "#include <color_fragment>",
        "#include <color_fragment>\ndiffuseColor.rgb = mix(diffuseColor.rgb, hairColour, clamp(vHair, 0.0, 1.0));",
      );
  };
}

export class FaceScene {
  constructor(canvas, data, background) {
    this.data = data;
    this.renderer = new WebGLRenderer({ canvas, antialias: true, preserveDrawingBuffer: true });
    this.renderer.setPixelRatio(window.devicePixelRatio || 1);
    this.renderer.localClippingEnabled = true;
    this.scene = new Scene();
    this.scene.background = new Color(background);
    this.root = new Group();
    this.root.scale.set(1, 1, -1);
    this.scene.add(this.root);
    this.camera = new OrthographicCamera(-1, 1, 1, -1, 1, 10000);
    this.scene.add(this.camera);
    this.scene.add(new AmbientLight(0xffffff, 0.55));
    const light = new DirectionalLight(0xffffff, 2.0);
    light.position.set(0.3, 0.5, 1.0);
    this.camera.add(light); // lit from the camera, as the toolkit's renderer is
    this.cut = new Plane(new Vector3(0, 0, -1), 0); // keeps model z >= 0 (world z <= 0)
    this._buildParts();
    this._buildPellets();
    this.controls = new OrbitControls(this.camera, canvas);
    this.controls.addEventListener("change", () => this.draw());
    this.skin = "solid";
  }

  _buildParts() {
    const mesh = this.data.mesh;
    this.positions = new BufferAttribute(new Float32Array(mesh.rest), 3);
    const colors = new Float32Array(mesh.colors.length);
    const c = new Color();
    for (let i = 0; i < mesh.colors.length; i += 3) {
      c.setRGB(mesh.colors[i] / 255, mesh.colors[i + 1] / 255, mesh.colors[i + 2] / 255, "srgb");
      colors[i] = c.r;
      colors[i + 1] = c.g;
      colors[i + 2] = c.b;
    }
    const colorAttr = new BufferAttribute(colors, 3);
    this.parts = {};
    for (const [name, faces] of Object.entries(mesh.parts)) {
      const geometry = new BufferGeometry();
      geometry.setAttribute("position", this.positions);
      geometry.setAttribute("color", colorAttr);
      geometry.setIndex(new BufferAttribute(faces, 1));
      geometry.computeVertexNormals();
      const material = new MeshLambertMaterial({ vertexColors: true, side: DoubleSide });
      if (name === "skin" && mesh.hair) withHair(geometry, material, mesh);
      const part = new Mesh(geometry, material);
      part.name = name;
      this.root.add(part);
      this.parts[name] = part;
    }
  }

  _buildPellets() {
    const p = this.data.pellets;
    const radius = this.data.views.marker_radius_mm;
    const sphere = new SphereGeometry(radius, 12, 8);
    const small = new SphereGeometry(0.7 * radius, 12, 8); // the measured one shows around it
    const make = (color) => new MeshBasicMaterial({ color: new Color(color) });
    this.measured = new Group();
    this.model = new Group();
    this.trails = [];
    this.measuredDots = [];
    this.modelDots = [];
    for (let j = 0; j < p.names.length; j++) {
      if (!p.shown[j]) continue;
      const dot = new Mesh(sphere, make("#e61414"));
      dot.renderOrder = 2;
      this.measured.add(dot);
      this.measuredDots.push([j, dot]);
      const trail = new BufferGeometry();
      trail.setAttribute("position", new BufferAttribute(new Float32Array(3 * p.trail_frames), 3));
      const line = new Line(trail, new LineBasicMaterial({ color: new Color("#e61414") }));
      line.frustumCulled = false;
      this.measured.add(line);
      this.trails.push([j, line]);
      const site = new Mesh(small, make("#1ab838"));
      site.renderOrder = 2;
      this.model.add(site);
      this.modelDots.push([j, site]);
    }
    // drawn over the face, as in the toolkit's side and inside views
    for (const group of [this.measured, this.model]) {
      group.traverse((o) => {
        if (o.material) o.material.depthTest = false;
      });
      this.root.add(group);
    }
  }

  setFrame(vertices, f) {
    this.positions.array.set(vertices);
    this.positions.needsUpdate = true;
    for (const part of Object.values(this.parts)) part.geometry.computeVertexNormals();
    const p = this.data.pellets;
    const n = p.names.length;
    const put = (dots, arr) => {
      for (const [j, dot] of dots) {
        const x = arr[2 * (f * n + j)];
        const y = arr[2 * (f * n + j) + 1];
        dot.visible = Number.isFinite(x) && Number.isFinite(y);
        if (dot.visible) dot.position.set(x, y, 0);
      }
    };
    put(this.measuredDots, p.measured);
    put(this.modelDots, p.model);
    for (const [j, line] of this.trails) {
      const pos = line.geometry.attributes.position;
      let count = 0;
      for (let g = Math.max(0, f - p.trail_frames + 1); g <= f; g++) {
        const x = p.measured[2 * (g * n + j)];
        const y = p.measured[2 * (g * n + j) + 1];
        if (!Number.isFinite(x) || !Number.isFinite(y)) continue;
        pos.array[3 * count] = x;
        pos.array[3 * count + 1] = y;
        pos.array[3 * count + 2] = 0;
        count++;
      }
      line.geometry.setDrawRange(0, count);
      pos.needsUpdate = true;
    }
  }

  setPart(name, shown) {
    if (this.parts[name]) this.parts[name].visible = shown;
  }

  setSkin(mode) {
    this.skin = mode;
    for (const [name, part] of Object.entries(this.parts)) {
      const m = part.material;
      if (name === "skin") {
        part.visible = mode !== "hidden" && this.skinShown !== false;
        m.transparent = mode === "see-through";
        m.opacity = mode === "see-through" ? 0.3 : 1.0;
        m.depthWrite = mode !== "see-through";
      }
      if (name === "palate") {
        // hidden skin (the top view): the palate see-through over the tongue, as the toolkit draws it
        m.transparent = mode === "hidden";
        m.opacity = mode === "hidden" ? 0.35 : 1.0;
        m.depthWrite = mode !== "hidden";
      }
      m.clippingPlanes = mode === "cut" && CUT_PARTS.has(name) ? [this.cut] : [];
      m.needsUpdate = true;
    }
  }

  setPellets(which, shown) {
    (which === "measured" ? this.measured : this.model).visible = shown;
  }

  // The paper's view `name`: the camera placed as cassi_fit.render places it for a canvas
  // of this size (the rest mesh's visible bounds, a margin of the canvas, at least
  // margin_mm around them).
  setPreset(name) {
    const v = this.data.views[name];
    const views = this.data.views;
    const canvas = this.renderer.domElement;
    const width = canvas.clientWidth;
    const height = canvas.clientHeight;
    const padW = v.extent[0] + 2 * views.margin_mm;
    const padH = v.extent[1] + 2 * views.margin_mm;
    const scale = Math.min(width / padW, height / padH) * (1 - 2 * views.margin);
    const centre = toWorld(v.centre);
    const toward = toWorld(v.toward);
    const distance = 2000;
    this.camera.left = -width / 2 / scale;
    this.camera.right = width / 2 / scale;
    this.camera.top = height / 2 / scale;
    this.camera.bottom = -height / 2 / scale;
    this.camera.near = 1;
    this.camera.far = 2 * distance;
    this.camera.zoom = 1;
    this.camera.position.copy(centre).addScaledVector(toward, distance);
    this.camera.up.copy(toWorld(v.up));
    this.camera.lookAt(centre);
    this.camera.updateProjectionMatrix();
    this.controls.target.copy(centre);
    this.controls.update();
    this.draw();
  }

  resize(width, height) {
    this.renderer.setSize(width, height, false);
  }

  draw() {
    this.renderer.render(this.scene, this.camera);
  }
}
