// fresco's GLB viewer: a small WebGL 1 viewer embedded in report.html and served by
// `fresco view`. It reads a GLB (glTF 2.0 binary) itself: every mesh primitive's POSITION,
// NORMAL, TEXCOORD_0, COLOR_0 and indices, and a material's base-colour texture when it is
// an embedded image. Drag to orbit, wheel to zoom, shift-drag or right-drag to pan,
// "W" or the button toggles the wireframe.
//
// frescoViewer(canvas, glbBytes, statusElement, up) returns a promise of
// {primitives, triangles, vertices, textures, nonBlank}; nonBlank is the fraction of canvas
// pixels that differ from the background after the first frame (the headless test reads it).
// `up` (optional, [x, y, z]) is the world's up in the model's frame, the axis the view orbits
// around; glTF's +Y when it is missing.
'use strict';

async function frescoViewer(canvas, glb, status, up) {
  const gl = canvas.getContext('webgl', { preserveDrawingBuffer: true, antialias: true });
  if (!gl) throw new Error('WebGL is not available in this browser');
  const uint32 = gl.getExtension('OES_element_index_uint');
  const BG = [0.09, 0.09, 0.11];

  // --- GLB container --------------------------------------------------------------------
  const view = new DataView(glb.buffer, glb.byteOffset, glb.byteLength);
  if (view.getUint32(0, true) !== 0x46546c67) throw new Error('not a GLB file (bad magic)');
  let json = null, bin = null;
  for (let off = 12; off + 8 <= glb.byteLength;) {
    const len = view.getUint32(off, true), type = view.getUint32(off + 4, true);
    const body = glb.subarray(off + 8, off + 8 + len);
    if (type === 0x4e4f534a) json = JSON.parse(new TextDecoder().decode(body));
    else if (type === 0x004e4942) bin = body;
    off += 8 + len;
  }
  if (!json) throw new Error('GLB without a JSON chunk');

  const COMPONENTS = { SCALAR: 1, VEC2: 2, VEC3: 3, VEC4: 4 };
  const ARRAYS = { 5120: Int8Array, 5121: Uint8Array, 5122: Int16Array, 5123: Uint16Array,
                   5125: Uint32Array, 5126: Float32Array };
  function accessor(i) {
    const a = json.accessors[i];
    const bv = json.bufferViews[a.bufferView];
    const Type = ARRAYS[a.componentType];
    const n = COMPONENTS[a.type];
    const start = bin.byteOffset + (bv.byteOffset || 0) + (a.byteOffset || 0);
    const stride = bv.byteStride || 0;
    if (stride && stride !== n * Type.BYTES_PER_ELEMENT) {
      // Interleaved: copy out element by element.
      const out = new Type(a.count * n);
      const dv = new DataView(bin.buffer);
      for (let k = 0; k < a.count; k++)
        for (let c = 0; c < n; c++)
          out[k * n + c] = new Type(bin.buffer.slice(start + k * stride + c * Type.BYTES_PER_ELEMENT,
                                                     start + k * stride + (c + 1) * Type.BYTES_PER_ELEMENT))[0];
      return { data: out, n, normalized: !!a.normalized, type: a.componentType };
    }
    const copy = bin.buffer.slice(start, start + a.count * n * Type.BYTES_PER_ELEMENT);
    return { data: new Type(copy), n, normalized: !!a.normalized, type: a.componentType };
  }

  async function texture(i) {
    const tex = json.textures[i];
    const img = json.images[tex.source];
    let blob;
    if (img.bufferView !== undefined) {
      const bv = json.bufferViews[img.bufferView];
      blob = new Blob([bin.subarray(bv.byteOffset || 0, (bv.byteOffset || 0) + bv.byteLength)],
                      { type: img.mimeType || 'image/png' });
    } else if (img.uri && img.uri.startsWith('data:')) {
      blob = await (await fetch(img.uri)).blob();
    } else {
      throw new Error('external texture ' + img.uri + ' is not supported');
    }
    const bitmap = await createImageBitmap(blob, { imageOrientation: 'none' });
    const t = gl.createTexture();
    gl.bindTexture(gl.TEXTURE_2D, t);
    gl.pixelStorei(gl.UNPACK_FLIP_Y_WEBGL, false);
    gl.texImage2D(gl.TEXTURE_2D, 0, gl.RGB, gl.RGB, gl.UNSIGNED_BYTE, bitmap);
    const pot = (v) => (v & (v - 1)) === 0;
    if (pot(bitmap.width) && pot(bitmap.height)) {
      gl.generateMipmap(gl.TEXTURE_2D);
      gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_MIN_FILTER, gl.LINEAR_MIPMAP_LINEAR);
    } else {
      gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_MIN_FILTER, gl.LINEAR);
    }
    gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_MAG_FILTER, gl.LINEAR);
    gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_WRAP_S, gl.CLAMP_TO_EDGE);
    gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_WRAP_T, gl.CLAMP_TO_EDGE);
    return t;
  }

  // --- shaders --------------------------------------------------------------------------
  const VS = `attribute vec3 p; attribute vec3 n; attribute vec2 uv; attribute vec4 col;
    uniform mat4 mvp; varying vec3 vn; varying vec2 vuv; varying vec4 vcol;
    void main() { vn = n; vuv = uv; vcol = col; gl_Position = mvp * vec4(p, 1.0); }`;
  const FS = `precision mediump float; varying vec3 vn; varying vec2 vuv; varying vec4 vcol;
    uniform sampler2D tex; uniform float textured; uniform float flat_; uniform vec3 light;
    void main() {
      vec3 base = textured > 0.5 ? texture2D(tex, vuv).rgb : vcol.rgb;
      if (flat_ > 0.5) { gl_FragColor = vec4(0.95, 0.75, 0.2, 1.0); return; }
      float l = textured > 0.5 ? 1.0 : 0.25 + 0.75 * abs(dot(normalize(vn), light));
      gl_FragColor = vec4(base * l, 1.0);
    }`;
  function shader(type, src) {
    const s = gl.createShader(type);
    gl.shaderSource(s, src);
    gl.compileShader(s);
    if (!gl.getShaderParameter(s, gl.COMPILE_STATUS)) throw new Error(gl.getShaderInfoLog(s));
    return s;
  }
  const prog = gl.createProgram();
  gl.attachShader(prog, shader(gl.VERTEX_SHADER, VS));
  gl.attachShader(prog, shader(gl.FRAGMENT_SHADER, FS));
  gl.linkProgram(prog);
  if (!gl.getProgramParameter(prog, gl.LINK_STATUS)) throw new Error(gl.getProgramInfoLog(prog));
  const loc = {};
  for (const a of ['p', 'n', 'uv', 'col']) loc[a] = gl.getAttribLocation(prog, a);
  for (const u of ['mvp', 'tex', 'textured', 'flat_', 'light']) loc[u] = gl.getUniformLocation(prog, u);

  // --- primitives -----------------------------------------------------------------------
  const lo = [Infinity, Infinity, Infinity], hi = [-Infinity, -Infinity, -Infinity];
  const prims = [];
  let triangles = 0, vertices = 0, textures = 0;
  const textureCache = new Map();
  for (const mesh of json.meshes || []) {
    for (const p of mesh.primitives) {
      if (p.mode !== undefined && p.mode !== 4) continue; // triangles only
      const pos = accessor(p.attributes.POSITION);
      const count = pos.data.length / 3;
      for (let k = 0; k < pos.data.length; k += 3)
        for (let c = 0; c < 3; c++) {
          lo[c] = Math.min(lo[c], pos.data[k + c]);
          hi[c] = Math.max(hi[c], pos.data[k + c]);
        }
      const buf = (data) => {
        const b = gl.createBuffer();
        gl.bindBuffer(gl.ARRAY_BUFFER, b);
        gl.bufferData(gl.ARRAY_BUFFER, data, gl.STATIC_DRAW);
        return b;
      };
      const prim = { pos: buf(pos.data), count };
      if (p.attributes.NORMAL !== undefined) prim.nrm = buf(accessor(p.attributes.NORMAL).data);
      if (p.attributes.TEXCOORD_0 !== undefined) prim.uv = buf(accessor(p.attributes.TEXCOORD_0).data);
      if (p.attributes.COLOR_0 !== undefined) {
        const c = accessor(p.attributes.COLOR_0);
        // glTF colours are linear: back to sRGB for display.
        const f = new Float32Array(count * 4);
        for (let k = 0; k < count; k++) {
          for (let j = 0; j < 4; j++) {
            let v = j < c.n ? c.data[k * c.n + j] : 1;
            if (c.type === 5121) v /= 255; else if (c.type === 5123) v /= 65535;
            f[k * 4 + j] = j < 3 ? Math.pow(v, 1 / 2.2) : v;
          }
        }
        prim.col = buf(f);
      }
      let idx = p.indices !== undefined ? accessor(p.indices).data : null;
      if (!idx) { idx = new Uint32Array(count); for (let k = 0; k < count; k++) idx[k] = k; }
      if (idx instanceof Uint32Array && !uint32) throw new Error('32-bit indices are not supported here');
      prim.idxType = idx instanceof Uint32Array ? gl.UNSIGNED_INT : idx instanceof Uint16Array ? gl.UNSIGNED_SHORT : gl.UNSIGNED_BYTE;
      prim.ibo = gl.createBuffer();
      gl.bindBuffer(gl.ELEMENT_ARRAY_BUFFER, prim.ibo);
      gl.bufferData(gl.ELEMENT_ARRAY_BUFFER, idx, gl.STATIC_DRAW);
      prim.nidx = idx.length;
      // Wireframe: each triangle edge once.
      const edges = new Set(), lines = [];
      for (let k = 0; k + 2 < idx.length; k += 3)
        for (let e = 0; e < 3; e++) {
          const a = idx[k + e], b = idx[k + (e + 1) % 3];
          const key = a < b ? a * 4294967296 + b : b * 4294967296 + a;
          if (!edges.has(key)) { edges.add(key); lines.push(a, b); }
        }
      const lineIdx = new Uint32Array(lines);
      prim.lbo = gl.createBuffer();
      gl.bindBuffer(gl.ELEMENT_ARRAY_BUFFER, prim.lbo);
      gl.bufferData(gl.ELEMENT_ARRAY_BUFFER, uint32 ? lineIdx : new Uint16Array(lineIdx), gl.STATIC_DRAW);
      prim.nlines = lineIdx.length;
      const mat = p.material !== undefined ? json.materials[p.material] : null;
      const ti = mat && mat.pbrMetallicRoughness && mat.pbrMetallicRoughness.baseColorTexture;
      if (ti && prim.uv) {
        if (!textureCache.has(ti.index)) { textureCache.set(ti.index, await texture(ti.index)); textures++; }
        prim.tex = textureCache.get(ti.index);
      }
      triangles += idx.length / 3;
      vertices += count;
      prims.push(prim);
    }
  }
  if (prims.length === 0) throw new Error('the GLB has no triangle mesh');

  // --- camera ---------------------------------------------------------------------------
  const centre = [0, 1, 2].map((c) => (lo[c] + hi[c]) / 2);
  const radius = Math.max(1e-6, Math.hypot(hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]) / 2);
  // The orbit's frame: `upAxis` and two horizontal axes (for +Y: x and z, as glTF's).
  const cross = (a, b) => [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]];
  const unit = (a) => { const l = Math.hypot(...a) || 1; return a.map((v) => v / l); };
  const upAxis = unit(Array.isArray(up) && up.length === 3 && Math.hypot(...up) > 0 ? up : [0, 1, 0]);
  const sideAxis = unit(cross(upAxis, Math.abs(upAxis[2]) < 0.9 ? [0, 0, 1] : [1, 0, 0]));
  const frontAxis = cross(sideAxis, upAxis);
  const cam = { yaw: 0.6, pitch: 0.35, dist: 2.6 * radius, target: centre.slice() };
  const home = JSON.parse(JSON.stringify(cam));
  let wire = false;

  function mul(a, b) {
    const o = new Float32Array(16);
    for (let i = 0; i < 4; i++) for (let j = 0; j < 4; j++) {
      let s = 0; for (let k = 0; k < 4; k++) s += a[k * 4 + j] * b[i * 4 + k]; o[i * 4 + j] = s;
    }
    return o;
  }
  function eye() {
    const cp = Math.cos(cam.pitch);
    const a = cp * Math.sin(cam.yaw), b = Math.sin(cam.pitch), c = cp * Math.cos(cam.yaw);
    return [0, 1, 2].map((i) =>
      cam.target[i] + cam.dist * (a * sideAxis[i] + b * upAxis[i] + c * frontAxis[i]));
  }
  function basis() {
    const e = eye();
    const f = [0, 1, 2].map((i) => cam.target[i] - e[i]);
    const fl = Math.hypot(...f); for (let i = 0; i < 3; i++) f[i] /= fl;
    let r = cross(f, upAxis);
    const rl = Math.hypot(...r) || 1; r = r.map((v) => v / rl);
    const u = [r[1] * f[2] - r[2] * f[1], r[2] * f[0] - r[0] * f[2], r[0] * f[1] - r[1] * f[0]];
    return { e, f, r, u };
  }
  function matrices() {
    const { e, f, r, u } = basis();
    const viewM = new Float32Array([r[0], u[0], -f[0], 0, r[1], u[1], -f[1], 0, r[2], u[2], -f[2], 0,
      -(r[0] * e[0] + r[1] * e[1] + r[2] * e[2]), -(u[0] * e[0] + u[1] * e[1] + u[2] * e[2]),
      (f[0] * e[0] + f[1] * e[1] + f[2] * e[2]), 1]);
    const aspect = canvas.width / canvas.height, fov = 45 * Math.PI / 180;
    const near = Math.max(cam.dist - 2 * radius, cam.dist * 0.01), far = cam.dist + 2 * radius;
    const t = 1 / Math.tan(fov / 2);
    const proj = new Float32Array([t / aspect, 0, 0, 0, 0, t, 0, 0, 0, 0, (far + near) / (near - far), -1,
      0, 0, 2 * far * near / (near - far), 0]);
    return { mvp: mul(proj, viewM), f };
  }

  function draw() {
    gl.viewport(0, 0, canvas.width, canvas.height);
    gl.clearColor(BG[0], BG[1], BG[2], 1);
    gl.clear(gl.COLOR_BUFFER_BIT | gl.DEPTH_BUFFER_BIT);
    gl.enable(gl.DEPTH_TEST);
    gl.useProgram(prog);
    const { mvp, f } = matrices();
    gl.uniformMatrix4fv(loc.mvp, false, mvp);
    gl.uniform3f(loc.light, -f[0], -f[1], -f[2]);
    gl.uniform1i(loc.tex, 0);
    for (const p of prims) {
      gl.bindBuffer(gl.ARRAY_BUFFER, p.pos);
      gl.enableVertexAttribArray(loc.p);
      gl.vertexAttribPointer(loc.p, 3, gl.FLOAT, false, 0, 0);
      const opt = (name, buf, n, fallback) => {
        if (loc[name] < 0) return;
        if (buf) {
          gl.bindBuffer(gl.ARRAY_BUFFER, buf);
          gl.enableVertexAttribArray(loc[name]);
          gl.vertexAttribPointer(loc[name], n, gl.FLOAT, false, 0, 0);
        } else {
          gl.disableVertexAttribArray(loc[name]);
          gl.vertexAttrib4f(loc[name], ...fallback);
        }
      };
      opt('n', p.nrm, 3, [0, 0, 1, 0]);
      opt('uv', p.uv, 2, [0, 0, 0, 0]);
      opt('col', p.col, 4, [0.8, 0.8, 0.78, 1]);
      gl.uniform1f(loc.textured, p.tex ? 1 : 0);
      if (p.tex) { gl.activeTexture(gl.TEXTURE0); gl.bindTexture(gl.TEXTURE_2D, p.tex); }
      gl.uniform1f(loc.flat_, 0);
      gl.enable(gl.POLYGON_OFFSET_FILL);
      gl.polygonOffset(1, 1);
      gl.bindBuffer(gl.ELEMENT_ARRAY_BUFFER, p.ibo);
      gl.drawElements(gl.TRIANGLES, p.nidx, p.idxType, 0);
      gl.disable(gl.POLYGON_OFFSET_FILL);
      if (wire) {
        gl.uniform1f(loc.flat_, 1);
        gl.bindBuffer(gl.ELEMENT_ARRAY_BUFFER, p.lbo);
        gl.drawElements(gl.LINES, p.nlines, uint32 ? gl.UNSIGNED_INT : gl.UNSIGNED_SHORT, 0);
      }
    }
  }

  // --- interaction ----------------------------------------------------------------------
  let drag = null;
  canvas.addEventListener('contextmenu', (e) => e.preventDefault());
  canvas.addEventListener('pointerdown', (e) => {
    drag = { x: e.clientX, y: e.clientY, pan: e.shiftKey || e.button === 2 };
    canvas.setPointerCapture(e.pointerId);
  });
  canvas.addEventListener('pointerup', () => { drag = null; });
  canvas.addEventListener('pointermove', (e) => {
    if (!drag) return;
    const dx = e.clientX - drag.x, dy = e.clientY - drag.y;
    drag.x = e.clientX; drag.y = e.clientY;
    if (drag.pan) {
      const { r, u } = basis();
      const s = cam.dist * 0.0015;
      for (let i = 0; i < 3; i++) cam.target[i] += (-dx * r[i] + dy * u[i]) * s;
    } else {
      cam.yaw -= dx * 0.008;
      cam.pitch = Math.max(-1.5, Math.min(1.5, cam.pitch + dy * 0.008));
    }
    draw();
  });
  canvas.addEventListener('wheel', (e) => {
    e.preventDefault();
    cam.dist = Math.max(radius * 0.05, Math.min(radius * 50, cam.dist * Math.exp(e.deltaY * 0.001)));
    draw();
  }, { passive: false });
  const api = {
    toggleWireframe() { wire = !wire; draw(); return wire; },
    reset() { Object.assign(cam, JSON.parse(JSON.stringify(home))); draw(); },
    draw,
  };
  canvas.tabIndex = 0;
  canvas.addEventListener('keydown', (e) => { if (e.key === 'w' || e.key === 'W') api.toggleWireframe(); });

  draw();
  // Fraction of pixels that are not the background: the headless test's "not blank".
  const px = new Uint8Array(canvas.width * canvas.height * 4);
  gl.readPixels(0, 0, canvas.width, canvas.height, gl.RGBA, gl.UNSIGNED_BYTE, px);
  const bg = BG.map((v) => Math.round(v * 255));
  let lit = 0;
  for (let k = 0; k < px.length; k += 4)
    if (Math.abs(px[k] - bg[0]) + Math.abs(px[k + 1] - bg[1]) + Math.abs(px[k + 2] - bg[2]) > 12) lit++;
  const result = { primitives: prims.length, triangles, vertices, textures,
                   nonBlank: lit / (canvas.width * canvas.height), api };
  if (status) status.textContent = `${triangles} triangles, ${vertices} vertices, ${textures} texture(s)`;
  return result;
}
