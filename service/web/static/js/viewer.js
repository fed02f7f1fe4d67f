// Before / after 3-D viewer (three.js, vendored): two panes sharing one camera and one orbit
// target, so that they always show the same view. Meshes as shaded triangles (flat or smooth,
// optional wireframe), curves as lines, clouds as points; 2-D data lie in the z = 0 plane and
// are seen from above. The result can be coloured by the per-point deviation.

import * as THREE from "three";
import { OrbitControls } from "three/addons/OrbitControls.js";

// viridis, sampled at 9 stops (sRGB)
const VIRIDIS = [
  [0.267, 0.005, 0.329], [0.283, 0.141, 0.458], [0.254, 0.265, 0.530], [0.207, 0.372, 0.553],
  [0.164, 0.471, 0.558], [0.128, 0.567, 0.551], [0.135, 0.659, 0.518], [0.267, 0.749, 0.441],
  [0.478, 0.821, 0.318], [0.741, 0.873, 0.150], [0.993, 0.906, 0.144],
];
const BASE_SURFACE = [0.66, 0.71, 0.80]; // lit meshes
const BASE_LINE = [0.22, 0.27, 0.36]; // curves and points on the light background
export const BACKGROUND = 0xeceef3;

export function colormap(t) {
  const x = Math.min(1, Math.max(0, Number.isFinite(t) ? t : 0)) * (VIRIDIS.length - 1);
  const i = Math.min(VIRIDIS.length - 2, Math.floor(x));
  const f = x - i;
  return VIRIDIS[i].map((c, k) => c + f * (VIRIDIS[i + 1][k] - c));
}

/** The colour bar of the legend (same map as the viewer). */
export function drawColorbar(canvas) {
  const ctx = canvas.getContext("2d");
  for (let x = 0; x < canvas.width; x++) {
    const [r, g, b] = colormap(x / (canvas.width - 1));
    ctx.fillStyle = `rgb(${255 * r},${255 * g},${255 * b})`;
    ctx.fillRect(x, 0, 1, canvas.height);
  }
}

function colors(n, values, vmax, base) {
  const out = new Float32Array(n * 3);
  const c = new THREE.Color();
  for (let i = 0; i < n; i++) {
    const rgb = values ? colormap(values[i] / (vmax || 1)) : base;
    c.setRGB(rgb[0], rgb[1], rgb[2], THREE.SRGBColorSpace); // stored linear
    out[3 * i] = c.r; out[3 * i + 1] = c.g; out[3 * i + 2] = c.b;
  }
  return out;
}

class Pane {
  constructor(container, camera) {
    this.container = container;
    this.camera = camera;
    this.renderer = new THREE.WebGLRenderer({ antialias: true, preserveDrawingBuffer: true });
    this.renderer.setPixelRatio(Math.min(2, window.devicePixelRatio || 1));
    this.renderer.setClearColor(BACKGROUND);
    container.replaceChildren(this.renderer.domElement);
    this.scene = new THREE.Scene();
    this.scene.add(new THREE.HemisphereLight(0xffffff, 0x404655, 1.4));
    this.light = new THREE.DirectionalLight(0xffffff, 1.6);
    this.scene.add(this.light);
    this.object = null;
  }

  size() { return [this.container.clientWidth || 400, this.container.clientHeight || 400]; }

  resize() { const [w, h] = this.size(); this.renderer.setSize(w, h, true); }

  set(object) {
    if (this.object) {
      this.scene.remove(this.object);
      this.object.geometry.dispose();
      this.object.material.dispose();
    }
    this.object = object;
    if (object) this.scene.add(object);
  }

  render() {
    this.light.position.copy(this.camera.position); // a headlight
    this.renderer.render(this.scene, this.camera);
  }
}

/** Whether WebGL runs on the CPU (SwiftShader, llvmpipe, ...): then the display budget is smaller. */
export function softwareRendering(renderer) {
  const gl = renderer.getContext();
  const ext = gl.getExtension("WEBGL_debug_renderer_info");
  const name = String(gl.getParameter(ext ? ext.UNMASKED_RENDERER_WEBGL : gl.RENDERER));
  return /swiftshader|llvmpipe|softpipe|software|basic render/i.test(name);
}

export class CompareViewer {
  constructor(beforeEl, afterEl) {
    this.camera = new THREE.PerspectiveCamera(40, 1, 1e-3, 1e3);
    this.panes = [new Pane(beforeEl, this.camera), new Pane(afterEl, this.camera)];
    this.controls = this.panes.map((p) => new OrbitControls(this.camera, p.renderer.domElement));
    this.controls[1].target = this.controls[0].target; // one shared target: synchronized views
    for (const c of this.controls) c.addEventListener("change", () => this.render());
    this.options = { shading: "smooth", wireframe: false, deviation: true, pointSize: 3 };
    this.data = null;
    this.software = softwareRendering(this.panes[0].renderer);
    new ResizeObserver(() => this.resize()).observe(beforeEl);
    this.resize();
  }

  resize() {
    this.panes.forEach((p) => p.resize());
    const [w, h] = this.panes[0].size();
    this.camera.aspect = w / h;
    this.camera.updateProjectionMatrix();
    this.render();
  }

  render() {
    this.panes.forEach((p) => p.render());
  }

  /**
   * @param {object} data {kind, dimension, before, after?, faces?, segments?, deviation?, vmax}
   *   positions as Float32 n*3 of the displayed vertices, connectivity in displayed indices.
   */
  show(data, { refit = true } = {}) {
    this.data = data;
    this.rebuild();
    if (refit) this.fit();
    this.render();
  }

  setOption(name, value) {
    this.options[name] = value;
    if (this.data) this.rebuild();
    this.render();
  }

  build(positions, values, vmax) {
    const d = this.data;
    const g = new THREE.BufferGeometry();
    const surface = d.faces && d.faces.length;
    const rgb = colors(positions.length / 3, values, vmax, surface ? BASE_SURFACE : BASE_LINE);
    g.setAttribute("position", new THREE.BufferAttribute(positions, 3));
    g.setAttribute("color", new THREE.BufferAttribute(rgb, 3));
    const o = this.options;
    if (surface) {
      g.setIndex(new THREE.BufferAttribute(d.faces, 1));
      g.computeVertexNormals();
      const m = new THREE.MeshStandardMaterial({ vertexColors: true, side: THREE.DoubleSide, roughness: 0.75,
        metalness: 0.0, flatShading: o.shading === "flat", wireframe: o.wireframe });
      return new THREE.Mesh(g, m);
    }
    if (d.segments && d.segments.length) {
      g.setIndex(new THREE.BufferAttribute(d.segments, 1));
      return new THREE.LineSegments(g, new THREE.LineBasicMaterial({ vertexColors: true }));
    }
    const m = new THREE.PointsMaterial({ vertexColors: true, size: o.pointSize, sizeAttenuation: false });
    return new THREE.Points(g, m);
  }

  rebuild() {
    const d = this.data;
    const dev = this.options.deviation && d.deviation ? d.deviation : null;
    this.panes[0].set(this.build(d.before, null, d.vmax));
    this.panes[1].set(d.after ? this.build(d.after, dev, d.vmax) : null);
  }

  fit() {
    const d = this.data;
    const g = new THREE.BufferGeometry();
    g.setAttribute("position", new THREE.BufferAttribute(d.before, 3));
    g.computeBoundingSphere();
    const { center, radius } = g.boundingSphere;
    const r = radius > 0 ? radius : 1;
    const dist = r / Math.sin((this.camera.fov * Math.PI) / 360) * 1.05;
    const planar = d.dimension === 2;
    const dir = planar ? new THREE.Vector3(0, 0, 1) : new THREE.Vector3(0.55, 0.35, 1).normalize();
    this.camera.near = dist / 1000;
    this.camera.far = dist * 10;
    this.camera.up.set(0, 1, 0);
    this.camera.position.copy(center).addScaledVector(dir, dist);
    this.camera.updateProjectionMatrix();
    for (const c of this.controls) {
      c.enableRotate = !planar; // 2-D data stay in their plane: pan and zoom only
      c.screenSpacePanning = true;
    }
    this.controls[0].target.copy(center);
    this.controls.forEach((c) => c.update());
    this.home = { position: this.camera.position.clone(), target: center.clone() };
  }

  reset() {
    if (!this.home) return;
    this.camera.position.copy(this.home.position);
    this.controls[0].target.copy(this.home.target);
    this.controls.forEach((c) => c.update());
    this.render();
  }
}
