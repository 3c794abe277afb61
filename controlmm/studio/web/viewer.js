// controlmm studio: a small WebGL 1 viewer of MuJoCo scenes, robot trajectories and human skeletons.
// World frame: MuJoCo's, Z up, metres. Meshes arrive in each geom's frame (see controlmm/studio/view.py).
"use strict";

const M4 = {
  identity() { const m = new Float32Array(16); m[0] = m[5] = m[10] = m[15] = 1; return m; },
  multiply(a, b) {
    const o = new Float32Array(16);
    for (let c = 0; c < 4; c++) for (let r = 0; r < 4; r++) {
      let s = 0;
      for (let k = 0; k < 4; k++) s += a[k * 4 + r] * b[c * 4 + k];
      o[c * 4 + r] = s;
    }
    return o;
  },
  // rigid transform from a position and a unit quaternion (w, x, y, z)
  pose(p, q) {
    const [w, x, y, z] = q, m = new Float32Array(16);
    m[0] = 1 - 2 * (y * y + z * z); m[1] = 2 * (x * y + w * z); m[2] = 2 * (x * z - w * y);
    m[4] = 2 * (x * y - w * z); m[5] = 1 - 2 * (x * x + z * z); m[6] = 2 * (y * z + w * x);
    m[8] = 2 * (x * z + w * y); m[9] = 2 * (y * z - w * x); m[10] = 1 - 2 * (x * x + y * y);
    m[12] = p[0]; m[13] = p[1]; m[14] = p[2]; m[15] = 1;
    return m;
  },
  translate(t) { const m = M4.identity(); m[12] = t[0]; m[13] = t[1]; m[14] = t[2]; return m; },
  perspective(fovy, aspect, near, far) {
    const f = 1 / Math.tan(fovy / 2), m = new Float32Array(16);
    m[0] = f / aspect; m[5] = f; m[10] = (far + near) / (near - far); m[11] = -1;
    m[14] = 2 * far * near / (near - far);
    return m;
  },
  lookAt(eye, at, up) {
    const sub = (a, b) => [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
    const norm = (v) => { const l = Math.hypot(...v) || 1; return [v[0] / l, v[1] / l, v[2] / l]; };
    const cross = (a, b) => [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]];
    const f = norm(sub(at, eye)), s = norm(cross(f, up)), u = cross(s, f), m = M4.identity();
    m[0] = s[0]; m[4] = s[1]; m[8] = s[2];
    m[1] = u[0]; m[5] = u[1]; m[9] = u[2];
    m[2] = -f[0]; m[6] = -f[1]; m[10] = -f[2];
    m[12] = -(s[0] * eye[0] + s[1] * eye[1] + s[2] * eye[2]);
    m[13] = -(u[0] * eye[0] + u[1] * eye[1] + u[2] * eye[2]);
    m[14] = f[0] * eye[0] + f[1] * eye[1] + f[2] * eye[2];
    return m;
  },
  invert(m) {
    const a = m, inv = new Float32Array(16);
    inv[0] = a[5] * a[10] * a[15] - a[5] * a[11] * a[14] - a[9] * a[6] * a[15] + a[9] * a[7] * a[14] + a[13] * a[6] * a[11] - a[13] * a[7] * a[10];
    inv[4] = -a[4] * a[10] * a[15] + a[4] * a[11] * a[14] + a[8] * a[6] * a[15] - a[8] * a[7] * a[14] - a[12] * a[6] * a[11] + a[12] * a[7] * a[10];
    inv[8] = a[4] * a[9] * a[15] - a[4] * a[11] * a[13] - a[8] * a[5] * a[15] + a[8] * a[7] * a[13] + a[12] * a[5] * a[11] - a[12] * a[7] * a[9];
    inv[12] = -a[4] * a[9] * a[14] + a[4] * a[10] * a[13] + a[8] * a[5] * a[14] - a[8] * a[6] * a[13] - a[12] * a[5] * a[10] + a[12] * a[6] * a[9];
    inv[1] = -a[1] * a[10] * a[15] + a[1] * a[11] * a[14] + a[9] * a[2] * a[15] - a[9] * a[3] * a[14] - a[13] * a[2] * a[11] + a[13] * a[3] * a[10];
    inv[5] = a[0] * a[10] * a[15] - a[0] * a[11] * a[14] - a[8] * a[2] * a[15] + a[8] * a[3] * a[14] + a[12] * a[2] * a[11] - a[12] * a[3] * a[10];
    inv[9] = -a[0] * a[9] * a[15] + a[0] * a[11] * a[13] + a[8] * a[1] * a[15] - a[8] * a[3] * a[13] - a[12] * a[1] * a[11] + a[12] * a[3] * a[9];
    inv[13] = a[0] * a[9] * a[14] - a[0] * a[10] * a[13] - a[8] * a[1] * a[14] + a[8] * a[2] * a[13] + a[12] * a[1] * a[10] - a[12] * a[2] * a[9];
    inv[2] = a[1] * a[6] * a[15] - a[1] * a[7] * a[14] - a[5] * a[2] * a[15] + a[5] * a[3] * a[14] + a[13] * a[2] * a[7] - a[13] * a[3] * a[6];
    inv[6] = -a[0] * a[6] * a[15] + a[0] * a[7] * a[14] + a[4] * a[2] * a[15] - a[4] * a[3] * a[14] - a[12] * a[2] * a[7] + a[12] * a[3] * a[6];
    inv[10] = a[0] * a[5] * a[15] - a[0] * a[7] * a[13] - a[4] * a[1] * a[15] + a[4] * a[3] * a[13] + a[12] * a[1] * a[7] - a[12] * a[3] * a[5];
    inv[14] = -a[0] * a[5] * a[14] + a[0] * a[6] * a[13] + a[4] * a[1] * a[14] - a[4] * a[2] * a[13] - a[12] * a[1] * a[6] + a[12] * a[2] * a[5];
    inv[3] = -a[1] * a[6] * a[11] + a[1] * a[7] * a[10] + a[5] * a[2] * a[11] - a[5] * a[3] * a[10] - a[9] * a[2] * a[7] + a[9] * a[3] * a[6];
    inv[7] = a[0] * a[6] * a[11] - a[0] * a[7] * a[10] - a[4] * a[2] * a[11] + a[4] * a[3] * a[10] + a[8] * a[2] * a[7] - a[8] * a[3] * a[6];
    inv[11] = -a[0] * a[5] * a[11] + a[0] * a[7] * a[9] + a[4] * a[1] * a[11] - a[4] * a[3] * a[9] - a[8] * a[1] * a[7] + a[8] * a[3] * a[5];
    inv[15] = a[0] * a[5] * a[10] - a[0] * a[6] * a[9] - a[4] * a[1] * a[10] + a[4] * a[2] * a[9] + a[8] * a[1] * a[6] - a[8] * a[2] * a[5];
    let det = a[0] * inv[0] + a[1] * inv[4] + a[2] * inv[8] + a[3] * inv[12];
    det = det ? 1 / det : 0;
    for (let i = 0; i < 16; i++) inv[i] *= det;
    return inv;
  },
  apply(m, v) {
    const x = v[0], y = v[1], z = v[2], w = v.length > 3 ? v[3] : 1;
    return [0, 1, 2, 3].map((r) => m[r] * x + m[4 + r] * y + m[8 + r] * z + m[12 + r] * w);
  },
};

function decode(b64, type) {
  const bin = atob(b64), bytes = new Uint8Array(bin.length);
  for (let i = 0; i < bin.length; i++) bytes[i] = bin.charCodeAt(i);
  return type === "u2" ? new Uint16Array(bytes.buffer) : type === "u4" ? new Uint32Array(bytes.buffer)
    : new Float32Array(bytes.buffer);
}

const VERTEX = `
attribute vec3 aPos; attribute vec3 aNormal;
uniform mat4 uModel; uniform mat4 uViewProj;
varying vec3 vNormal;
void main() { vNormal = mat3(uModel) * aNormal; gl_Position = uViewProj * uModel * vec4(aPos, 1.0); }`;
const FRAGMENT = `
precision mediump float;
uniform vec4 uColor; uniform float uLit; varying vec3 vNormal;
void main() {
  vec3 n = normalize(vNormal); if (!gl_FrontFacing) n = -n;
  float d = max(dot(n, normalize(vec3(0.4, 0.3, 0.85))), 0.0) * 0.65
          + max(dot(n, normalize(vec3(-0.5, -0.6, 0.2))), 0.0) * 0.2 + 0.3;
  gl_FragColor = vec4(mix(uColor.rgb, uColor.rgb * d, uLit), uColor.a);
}`;

const COLORS = {
  failing: [0.95, 0.12, 0.1, 1], hitObstacle: [1.0, 0.55, 0.1, 1], human: [0.15, 0.45, 0.95, 1],
  target: [0.1, 0.75, 0.25, 1], achieved: [0.15, 0.45, 0.95, 1], miss: [0.95, 0.2, 0.15, 1],
  contact: [1.0, 0.0, 0.6, 1], placing: [1.0, 0.85, 0.0, 1], grid: [0.55, 0.58, 0.62, 1],
};

class Viewer {
  constructor(canvas, overlay) {
    this.canvas = canvas;
    this.overlay = overlay;
    const gl = canvas.getContext("webgl", { antialias: true, preserveDrawingBuffer: true });
    this.gl = gl;
    this.ok = !!gl;
    this.geometry = null;   // scene_geometry document
    this.view = null;       // view document (rounds) or null for a preview
    this.time = 0;
    this.show = { robot: true, human: true, contacts: true, targets: true, sideBySide: false };
    this.round = 0;         // index into view.rounds
    this.edits = [];        // targets being edited: {joint, frame, position, active}
    this.camera = { target: [0, 0, 0.8], yaw: -2.3, pitch: 0.35, dist: 4.2 };
    this.stats = { geoms: 0, robotGeoms: 0, panels: 0, frames: 0, failing: 0, contacts: 0 };
    this.onPick = null;     // callback(x, y) when the view is clicked in placing mode
    if (!gl) return;
    const prog = gl.createProgram();
    for (const [type, src] of [[gl.VERTEX_SHADER, VERTEX], [gl.FRAGMENT_SHADER, FRAGMENT]]) {
      const sh = gl.createShader(type);
      gl.shaderSource(sh, src); gl.compileShader(sh); gl.attachShader(prog, sh);
    }
    gl.linkProgram(prog); gl.useProgram(prog);
    this.loc = {
      aPos: gl.getAttribLocation(prog, "aPos"), aNormal: gl.getAttribLocation(prog, "aNormal"),
      uModel: gl.getUniformLocation(prog, "uModel"), uViewProj: gl.getUniformLocation(prog, "uViewProj"),
      uColor: gl.getUniformLocation(prog, "uColor"), uLit: gl.getUniformLocation(prog, "uLit"),
    };
    gl.enable(gl.DEPTH_TEST);
    gl.enable(gl.BLEND); gl.blendFunc(gl.SRC_ALPHA, gl.ONE_MINUS_SRC_ALPHA);
    gl.enable(gl.SCISSOR_TEST);
    this.sphere = this.upload(Viewer.sphereMesh(0.5));
    this.lineBuffer = gl.createBuffer();
    this.bindMouse();
    this.requestDraw();
  }

  static sphereMesh(r) {
    const v = [], f = [], rings = 8, segs = 12;
    for (let i = 0; i <= rings; i++) for (let j = 0; j < segs; j++) {
      const th = Math.PI * i / rings, ph = 2 * Math.PI * j / segs;
      v.push(r * Math.sin(th) * Math.cos(ph), r * Math.sin(th) * Math.sin(ph), r * Math.cos(th));
    }
    for (let i = 0; i < rings; i++) for (let j = 0; j < segs; j++) {
      const a = i * segs + j, b = i * segs + (j + 1) % segs;
      f.push(a, a + segs, b + segs, a, b + segs, b);
    }
    return { vertices: new Float32Array(v), faces: new Uint32Array(f) };
  }

  // indexed mesh -> flat-shaded triangles in a GPU buffer
  upload(mesh) {
    const gl = this.gl, v = mesh.vertices, f = mesh.faces, n = f.length;
    const data = new Float32Array(n * 6);
    for (let t = 0; t < n; t += 3) {
      const p = [0, 1, 2].map((k) => [v[3 * f[t + k]], v[3 * f[t + k] + 1], v[3 * f[t + k] + 2]]);
      const e1 = [p[1][0] - p[0][0], p[1][1] - p[0][1], p[1][2] - p[0][2]];
      const e2 = [p[2][0] - p[0][0], p[2][1] - p[0][1], p[2][2] - p[0][2]];
      let nx = e1[1] * e2[2] - e1[2] * e2[1], ny = e1[2] * e2[0] - e1[0] * e2[2], nz = e1[0] * e2[1] - e1[1] * e2[0];
      const l = Math.hypot(nx, ny, nz) || 1; nx /= l; ny /= l; nz /= l;
      for (let k = 0; k < 3; k++) data.set([p[k][0], p[k][1], p[k][2], nx, ny, nz], (t + k) * 6);
    }
    const buf = gl.createBuffer();
    gl.bindBuffer(gl.ARRAY_BUFFER, buf); gl.bufferData(gl.ARRAY_BUFFER, data, gl.STATIC_DRAW);
    return { buf, count: n };
  }

  setGeometry(doc) {
    if (this.geometry && this.geometry.id === doc.id) return;
    this.geometry = doc;
    this.meshes = {};
    if (!this.ok) return;
    for (const [key, m] of Object.entries(doc.meshes)) {
      this.meshes[key] = this.upload({ vertices: decode(m.vertices), faces: decode(m.faces, m.index) });
    }
    for (const g of doc.geoms) g.local = M4.pose(g.pos, g.quat);
    this.startPoses = decode(doc.start_poses);
    const s = doc.start;
    this.camera.target = [s.x + 0.8 * Math.cos(s.yaw), s.y + 0.8 * Math.sin(s.yaw), 0.7];
    this.camera.yaw = s.yaw - 2.3;
    this.requestDraw();
  }

  setView(view) {
    this.view = view;
    for (const r of view.rounds) {
      r.posesArr = decode(r.poses);
      r.humanArr = decode(r.human);
      r.duration = Math.max((r.num_frames - 1) / r.fps, 0);
    }
    this.round = Math.max(0, view.rounds.findIndex((r) => r.index === view.chosen));
    this.time = 0;
    this.requestDraw();
  }

  clearView() { this.view = null; this.time = 0; this.requestDraw(); }

  duration() {
    if (!this.view) return 0;
    return Math.max(...this.view.rounds.map((r) => r.duration));
  }

  lateral() {
    const yaw = this.geometry ? this.geometry.start.yaw : 0;
    return [-Math.sin(yaw), Math.cos(yaw)];
  }

  requestDraw() {
    if (this.pending || !this.ok) return;
    this.pending = true;
    requestAnimationFrame(() => { this.pending = false; this.draw(); });
  }

  viewProj(w, h) {
    const c = this.camera, cp = Math.cos(c.pitch);
    const eye = [c.target[0] + c.dist * cp * Math.cos(c.yaw), c.target[1] + c.dist * cp * Math.sin(c.yaw),
      c.target[2] + c.dist * Math.sin(c.pitch)];
    return M4.multiply(M4.perspective(0.8, w / Math.max(h, 1), 0.05, 60), M4.lookAt(eye, c.target, [0, 0, 1]));
  }

  panels() {
    const rounds = this.view ? this.view.rounds : [];
    const list = this.show.sideBySide && rounds.length > 1 ? rounds.map((_, i) => i) : [this.view ? this.round : -1];
    const w = this.canvas.width, h = this.canvas.height, n = list.length;
    return list.map((r, i) => ({ round: r, x: Math.round(i * w / n), y: 0, w: Math.round(w / n), h }));
  }

  resize() {
    const dpr = window.devicePixelRatio || 1, rect = this.canvas.getBoundingClientRect();
    const w = Math.max(1, Math.round(rect.width * dpr)), h = Math.max(1, Math.round(rect.height * dpr));
    if (this.canvas.width !== w || this.canvas.height !== h) { this.canvas.width = w; this.canvas.height = h; }
  }

  draw() {
    const gl = this.gl;
    this.resize();
    gl.scissor(0, 0, this.canvas.width, this.canvas.height);
    gl.clearColor(0.93, 0.94, 0.96, 1); gl.clear(gl.COLOR_BUFFER_BIT | gl.DEPTH_BUFFER_BIT);
    this.stats = { geoms: 0, robotGeoms: 0, panels: 0, frames: 0, failing: 0, contacts: 0, labels: 0 };
    this.labels = [];
    this.lastPanels = this.panels();
    if (!this.geometry) { this.placeLabels(); return; }
    for (const p of this.lastPanels) this.drawPanel(p);
    this.placeLabels();
    this.canvas.dataset.robotGeoms = String(this.stats.robotGeoms);
    this.canvas.dataset.geoms = String(this.stats.geoms);
    this.canvas.dataset.panels = String(this.stats.panels);
    this.canvas.dataset.failing = String(this.stats.failing);
    this.canvas.dataset.contacts = String(this.stats.contacts);
  }

  frameOf(r) {
    return Math.min(r.num_frames - 1, Math.max(0, Math.round(this.time * r.fps)));
  }

  drawPanel(p) {
    const gl = this.gl, L = this.loc, geo = this.geometry;
    gl.viewport(p.x, p.y, p.w, p.h); gl.scissor(p.x, p.y, p.w, p.h);
    gl.clear(gl.DEPTH_BUFFER_BIT);
    const vp = this.viewProj(p.w, p.h);
    p.vp = vp;
    gl.uniformMatrix4fv(L.uViewProj, false, vp);
    this.stats.panels += 1;
    const r = p.round >= 0 ? this.view.rounds[p.round] : null;
    const frame = r ? this.frameOf(r) : 0;
    const poses = r ? r.posesArr : this.startPoses, nb = geo.bodies.length, base = frame * nb * 7;
    const bodyM = [];
    for (let b = 0; b < nb; b++) {
      const o = base + b * 7;
      bodyM.push(M4.pose([poses[o], poses[o + 1], poses[o + 2]], [poses[o + 3], poses[o + 4], poses[o + 5], poses[o + 6]]));
    }
    // what fails at this frame: robot bodies (red) and the obstacle geoms they hit (orange)
    const failingBodies = new Set(), hitGeoms = new Set();
    if (r) {
      for (const f of r.failures) {
        if (f.severity !== "error" || frame < f.frame_start || frame > f.frame_end) continue;
        if (f.robot_body) failingBodies.add(f.robot_body);
        if (f.kind === "self_collision" && f.obstacle_geom) failingBodies.add(f.obstacle_geom);
        else if (f.obstacle_geom) hitGeoms.add(f.obstacle_geom);
      }
    }
    this.stats.failing += failingBodies.size;
    const transparent = [];
    for (const g of geo.geoms) {
      if (g.kind === "robot" && !this.show.robot) continue;
      const model = g.body >= 0 ? M4.multiply(bodyM[g.body], g.local) : g.local;
      let color = g.rgba;
      if (g.kind === "robot" && failingBodies.has(g.body_name)) color = COLORS.failing;
      if (g.kind !== "robot" && hitGeoms.has(g.name)) color = COLORS.hitObstacle;
      if (g.kind === "floor") color = [0.8, 0.82, 0.85, 0.55];
      if (color[3] < 0.999) { transparent.push([g, model, color]); continue; }
      this.drawMesh(this.meshes[g.mesh], model, color);
      this.stats.geoms += 1;
      if (g.kind === "robot") this.stats.robotGeoms += 1;
    }
    this.drawGrid(geo.floor_z + 0.001);
    if (r && this.show.human && !this.show.sideBySide) this.drawHuman(r);
    if (r && this.show.targets) this.drawTargets(r, frame);
    if (!r || this.show.targets) this.drawEdits();
    if (r && this.show.contacts) {
      for (const c of r.contacts) {
        if (Math.abs(c[0] - frame) > 1) continue;
        this.drawSphere([c[1], c[2], c[3]], 0.035, COLORS.contact);
        this.stats.contacts += 1;
      }
    }
    gl.depthMask(false);
    for (const [g, model, color] of transparent) {
      this.drawMesh(this.meshes[g.mesh], model, color);
      this.stats.geoms += 1;
      if (g.kind === "robot") this.stats.robotGeoms += 1;
    }
    gl.depthMask(true);
    if (r && this.show.sideBySide) {
      this.labels.push({ text: `round ${r.index}: ${r.passed ? "pass" : "fail"}`, px: p.x + 8, py: p.y + 8, screen: true });
    }
  }

  drawMesh(mesh, model, color) {
    if (!mesh) return;
    const gl = this.gl, L = this.loc;
    gl.bindBuffer(gl.ARRAY_BUFFER, mesh.buf);
    gl.enableVertexAttribArray(L.aPos); gl.enableVertexAttribArray(L.aNormal);
    gl.vertexAttribPointer(L.aPos, 3, gl.FLOAT, false, 24, 0);
    gl.vertexAttribPointer(L.aNormal, 3, gl.FLOAT, false, 24, 12);
    gl.uniformMatrix4fv(L.uModel, false, model);
    gl.uniform4fv(L.uColor, color); gl.uniform1f(L.uLit, 1);
    gl.drawArrays(gl.TRIANGLES, 0, mesh.count);
  }

  drawSphere(p, radius, color) {
    const m = M4.translate(p);
    m[0] = m[5] = m[10] = radius * 2;  // the unit sphere mesh has radius 0.5
    this.drawMesh(this.sphere, m, color);
  }

  drawLines(points, color) {
    if (!points.length) return;
    const gl = this.gl, L = this.loc;
    gl.bindBuffer(gl.ARRAY_BUFFER, this.lineBuffer);
    gl.bufferData(gl.ARRAY_BUFFER, new Float32Array(points), gl.DYNAMIC_DRAW);
    gl.enableVertexAttribArray(L.aPos); gl.disableVertexAttribArray(L.aNormal);
    gl.vertexAttrib3f(L.aNormal, 0, 0, 1);
    gl.vertexAttribPointer(L.aPos, 3, gl.FLOAT, false, 12, 0);
    gl.uniformMatrix4fv(L.uModel, false, M4.identity());
    gl.uniform4fv(L.uColor, color); gl.uniform1f(L.uLit, 0);
    gl.drawArrays(gl.LINES, 0, points.length / 3);
  }

  drawGrid(z) {
    const c = this.camera.target, pts = [], n = 12;
    const cx = Math.round(c[0]), cy = Math.round(c[1]);
    for (let i = -n; i <= n; i++) {
      pts.push(cx + i * 0.5, cy - n * 0.5, z, cx + i * 0.5, cy + n * 0.5, z);
      pts.push(cx - n * 0.5, cy + i * 0.5, z, cx + n * 0.5, cy + i * 0.5, z);
    }
    this.drawLines(pts, [...COLORS.grid.slice(0, 3), 0.5]);
  }

  humanJoints(r) {
    const T = r.humanArr.length / 66, f = Math.min(T - 1, Math.max(0, Math.round(this.time * r.human_fps)));
    const [lx, ly] = this.lateral(), off = 1.0, out = [];
    for (let j = 0; j < 22; j++) {
      const o = (f * 22 + j) * 3;
      out.push([r.humanArr[o] + lx * off, r.humanArr[o + 1] + ly * off, r.humanArr[o + 2]]);
    }
    return out;
  }

  drawHuman(r) {
    const joints = this.humanJoints(r), parents = this.view.skeleton.parents, pts = [];
    for (let j = 1; j < joints.length; j++) pts.push(...joints[parents[j]], ...joints[j]);
    this.drawLines(pts, COLORS.human);
    for (const p of joints) this.drawSphere(p, 0.03, COLORS.human);
    this.labels.push({ text: "human", pos: joints[15] });
  }

  drawTargets(r, frame) {
    const humanFrame = Math.round(this.time * r.human_fps);
    for (const t of r.targets) {
      const near = Math.abs(t.frame - humanFrame) <= 2;
      const miss = t.error_m !== null && t.error_m > 0.02;
      this.drawSphere(t.target, near ? 0.07 : 0.05, COLORS.target);
      this.drawSphere(t.achieved, 0.04, COLORS.achieved);
      this.drawLines([...t.target, ...t.achieved], miss ? COLORS.miss : COLORS.target);
      const err = t.error_m === null ? "" : ` ${(t.error_m * 100).toFixed(1)} cm`;
      this.labels.push({ text: `${t.joint}@${t.frame}${err}`, pos: t.target });
    }
  }

  drawEdits() {
    for (const e of this.edits) {
      if (!e.position.every(Number.isFinite)) continue;
      this.drawSphere(e.position, e.active ? 0.08 : 0.06, e.active ? COLORS.placing : COLORS.target);
      const p = e.position;
      this.drawLines([p[0], p[1], this.geometry.floor_z, ...p], e.active ? COLORS.placing : COLORS.target);
      this.labels.push({ text: `${e.joint}@${e.frame}`, pos: p });
    }
  }

  // overlay labels at projected points (HTML, so text stays sharp)
  placeLabels() {
    if (!this.overlay) return;
    const dpr = window.devicePixelRatio || 1, html = [], panel = this.lastPanels;
    for (const l of this.labels) {
      let x, y;
      if (l.screen) { x = l.px / dpr; y = l.py / dpr; } else {
        const p0 = panel[0];
        if (!p0.vp) continue;
        const c = M4.apply(p0.vp, l.pos);
        if (c[3] <= 0) continue;
        x = (p0.x + (c[0] / c[3] * 0.5 + 0.5) * p0.w) / dpr;
        y = (this.canvas.height - (c[1] / c[3] * 0.5 + 0.5) * p0.h) / dpr;
      }
      html.push(`<span class="label" style="left:${x.toFixed(0)}px;top:${y.toFixed(0)}px">${l.text}</span>`);
    }
    this.overlay.innerHTML = html.join("");
    this.stats.labels = html.length;
  }

  // the point where a click ray meets the horizontal plane z = height (world m), or null
  pick(clientX, clientY, height) {
    const rect = this.canvas.getBoundingClientRect(), dpr = window.devicePixelRatio || 1;
    const px = (clientX - rect.left) * dpr, py = this.canvas.height - (clientY - rect.top) * dpr;
    const p = (this.lastPanels || this.panels()).find((q) => px >= q.x && px < q.x + q.w) || this.panels()[0];
    const inv = M4.invert(this.viewProj(p.w, p.h));
    const nx = (px - p.x) / p.w * 2 - 1, ny = py / p.h * 2 - 1;
    const a = M4.apply(inv, [nx, ny, -1, 1]), b = M4.apply(inv, [nx, ny, 1, 1]);
    const A = [a[0] / a[3], a[1] / a[3], a[2] / a[3]], B = [b[0] / b[3], b[1] / b[3], b[2] / b[3]];
    if (Math.abs(B[2] - A[2]) < 1e-9) return null;
    const s = (height - A[2]) / (B[2] - A[2]);
    if (s < 0) return null;
    return [A[0] + s * (B[0] - A[0]), A[1] + s * (B[1] - A[1])];
  }

  bindMouse() {
    const c = this.canvas;
    let drag = null;
    c.addEventListener("contextmenu", (e) => e.preventDefault());
    c.addEventListener("mousedown", (e) => { drag = { x: e.clientX, y: e.clientY, button: e.button, shift: e.shiftKey, moved: 0 }; });
    window.addEventListener("mouseup", (e) => {
      if (drag && drag.moved < 4 && this.onPick) this.onPick(e.clientX, e.clientY);
      drag = null;
    });
    window.addEventListener("mousemove", (e) => {
      if (!drag) return;
      const dx = e.clientX - drag.x, dy = e.clientY - drag.y;
      drag.moved += Math.abs(dx) + Math.abs(dy);
      drag.x = e.clientX; drag.y = e.clientY;
      const cam = this.camera;
      if (drag.button === 2 || drag.shift) {
        const s = cam.dist * 0.0015, cy = Math.cos(cam.yaw), sy = Math.sin(cam.yaw);
        cam.target[0] += (sy * dx - cy * dy * Math.sin(cam.pitch)) * s;
        cam.target[1] += (-cy * dx - sy * dy * Math.sin(cam.pitch)) * s;
        cam.target[2] += dy * Math.cos(cam.pitch) * s;
      } else {
        cam.yaw -= dx * 0.008;
        cam.pitch = Math.min(1.5, Math.max(-0.2, cam.pitch + dy * 0.006));
      }
      this.requestDraw();
    });
    c.addEventListener("wheel", (e) => {
      e.preventDefault();
      this.camera.dist = Math.min(30, Math.max(0.5, this.camera.dist * Math.exp(e.deltaY * 0.001)));
      this.requestDraw();
    }, { passive: false });
    window.addEventListener("resize", () => this.requestDraw());
  }
}

window.StudioViewer = Viewer;
