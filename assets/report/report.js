// The report page of `pipeline report` (src/report/mod.rs writes the data it reads):
// a three.js view of the fitted model (linear blend skinning of the coarse t0 model by each
// frame's bone matrices), the skeleton, the frame's surfaces, a slider and play button that
// drive the view, the overlay pictures and the health plots together.
(function () {
  'use strict';
  const data = JSON.parse(document.getElementById('report-data').textContent);
  const frames = data.frames;
  const nb = data.bones.length;
  const pad = (f) => String(f).padStart(6, '0');
  const el = (id) => document.getElementById(id);
  const svgNS = 'http://www.w3.org/2000/svg';
  const CLEAR = 0x20242a;

  // ---- 3D view ----
  const container = el('view3d');
  // A browser without WebGL (software rendering off, no GL driver) keeps everything but the
  // 3D view.
  let renderer = null;
  try {
    renderer = new THREE.WebGLRenderer({ antialias: true, preserveDrawingBuffer: true });
    renderer.setPixelRatio(window.devicePixelRatio || 1);
    renderer.setClearColor(CLEAR);
    container.appendChild(renderer.domElement);
  } catch (e) {
    renderer = null;
    const note = document.createElement('p');
    note.id = 'no-webgl';
    note.textContent = 'The 3D view needs WebGL, which this browser has turned off or cannot create (' + e.message + '). The slider, pictures and plots work without it.';
    note.style.color = '#eee';
    note.style.padding = '1rem';
    container.appendChild(note);
  }
  const scene = new THREE.Scene();
  scene.add(new THREE.HemisphereLight(0xffffff, 0x404040, 2.0));
  const sun = new THREE.DirectionalLight(0xffffff, 1.5);
  sun.position.set(3, 6, 4);
  scene.add(sun);
  const camera = new THREE.PerspectiveCamera(35, 4 / 3, 0.01, 200);

  const m = data.model;
  const rest = new Float32Array(m.positions);
  const nv = rest.length / 3;
  const skinBone = new Uint16Array(nv * 4);
  const skinWeight = new Float32Array(nv * 4);
  m.skin.forEach((s, k) => { skinBone[k] = s[0]; skinWeight[k] = s[1]; });
  const posed = new Float32Array(rest.length);
  const modelGeom = new THREE.BufferGeometry();
  modelGeom.setAttribute('position', new THREE.BufferAttribute(posed, 3));
  modelGeom.setAttribute('color', new THREE.BufferAttribute(new Float32Array(m.colours), 3));
  modelGeom.setIndex(m.indices);
  const model = new THREE.Mesh(modelGeom, new THREE.MeshLambertMaterial({ vertexColors: true, side: THREE.DoubleSide }));
  scene.add(model);

  const bonePositions = new Float32Array(nb * 6);
  const skeletonGeom = new THREE.BufferGeometry();
  skeletonGeom.setAttribute('position', new THREE.BufferAttribute(bonePositions, 3));
  const skeleton = new THREE.LineSegments(skeletonGeom, new THREE.LineBasicMaterial({ color: 0xffe14d, depthTest: false }));
  skeleton.renderOrder = 10;
  scene.add(skeleton);
  const jointGeom = new THREE.BufferGeometry();
  jointGeom.setAttribute('position', new THREE.BufferAttribute(bonePositions, 3));
  const joints = new THREE.Points(jointGeom, new THREE.PointsMaterial({ color: 0xffffff, size: 5, sizeAttenuation: false, depthTest: false }));
  joints.renderOrder = 11;
  scene.add(joints);

  const surfaceMaterials = {
    graphcut: new THREE.MeshLambertMaterial({ color: 0xbfc8d0, transparent: true, opacity: 0.45, side: THREE.DoubleSide, depthWrite: false }),
    hull: new THREE.MeshBasicMaterial({ color: 0x4da3ff, wireframe: true, transparent: true, opacity: 0.35 }),
    tracked: new THREE.MeshLambertMaterial({ color: 0xe8a15c, transparent: true, opacity: 0.6, side: THREE.DoubleSide, depthWrite: false }),
  };
  const surfaceKinds = ['graphcut', 'hull', 'tracked'];
  const surfaces = { graphcut: null, hull: null, tracked: null };
  const surfaceCache = new Map();
  function surfaceMesh(kind, f) {
    const key = kind + '-' + f;
    if (!surfaceCache.has(key)) {
      const node = el('surface-' + key);
      let mesh = null;
      if (node) {
        const s = JSON.parse(node.textContent);
        const g = new THREE.BufferGeometry();
        g.setAttribute('position', new THREE.BufferAttribute(Float32Array.from(s.v, (x) => x / 1000), 3));
        g.setIndex(s.t);
        g.computeVertexNormals();
        mesh = new THREE.Mesh(g, surfaceMaterials[kind]);
      }
      surfaceCache.set(key, mesh);
    }
    return surfaceCache.get(key);
  }

  function apply(M, b, x, y, z, out, o) {
    const k = 12 * b;
    out[o] = M[k] * x + M[k + 1] * y + M[k + 2] * z + M[k + 3];
    out[o + 1] = M[k + 4] * x + M[k + 5] * y + M[k + 6] * z + M[k + 7];
    out[o + 2] = M[k + 8] * x + M[k + 9] * y + M[k + 10] * z + M[k + 11];
  }
  const tmp = new Float32Array(3);
  function pose(i) {
    const M = data.motion[i];
    for (let v = 0; v < nv; v++) {
      const x = rest[3 * v], y = rest[3 * v + 1], z = rest[3 * v + 2];
      let px = 0, py = 0, pz = 0;
      for (let k = 0; k < 4; k++) {
        const w = skinWeight[4 * v + k];
        if (w === 0) continue;
        apply(M, skinBone[4 * v + k], x, y, z, tmp, 0);
        px += w * tmp[0]; py += w * tmp[1]; pz += w * tmp[2];
      }
      posed[3 * v] = px; posed[3 * v + 1] = py; posed[3 * v + 2] = pz;
    }
    modelGeom.attributes.position.needsUpdate = true;
    modelGeom.computeVertexNormals();
    modelGeom.computeBoundingSphere();
    data.bones.forEach((bone, b) => {
      apply(M, b, bone.head[0], bone.head[1], bone.head[2], bonePositions, 6 * b);
      apply(M, b, bone.tail[0], bone.tail[1], bone.tail[2], bonePositions, 6 * b + 3);
    });
    skeletonGeom.attributes.position.needsUpdate = true;
    jointGeom.attributes.position.needsUpdate = true;
  }

  // Orbit camera about the model's centre at the first frame.
  pose(0);
  modelGeom.computeBoundingBox();
  const box = modelGeom.boundingBox;
  const target = box.getCenter(new THREE.Vector3());
  const size = box.getSize(new THREE.Vector3());
  const orbit = { azimuth: 0.6, elevation: 0.25, distance: 1.9 * Math.max(size.x, size.y, size.z, 0.5) };
  function placeCamera() {
    const e = orbit.elevation, a = orbit.azimuth, d = orbit.distance;
    camera.position.set(target.x + d * Math.cos(e) * Math.sin(a), target.y + d * Math.sin(e), target.z + d * Math.cos(e) * Math.cos(a));
    camera.lookAt(target);
  }
  let drag = null;
  container.addEventListener('pointerdown', (ev) => { drag = { x: ev.clientX, y: ev.clientY }; container.setPointerCapture(ev.pointerId); });
  container.addEventListener('pointerup', () => { drag = null; });
  container.addEventListener('pointermove', (ev) => {
    if (!drag) return;
    orbit.azimuth -= (ev.clientX - drag.x) * 0.01;
    orbit.elevation = Math.max(-1.4, Math.min(1.4, orbit.elevation + (ev.clientY - drag.y) * 0.01));
    drag = { x: ev.clientX, y: ev.clientY };
    render();
  });
  container.addEventListener('wheel', (ev) => {
    ev.preventDefault();
    orbit.distance *= Math.exp(ev.deltaY * 0.001);
    render();
  }, { passive: false });

  function resize() {
    if (!renderer) return;
    const w = container.clientWidth || 640, h = container.clientHeight || 480;
    renderer.setSize(w, h);
    camera.aspect = w / h;
    camera.updateProjectionMatrix();
  }
  function render() {
    if (!renderer) return;
    placeCamera();
    renderer.render(scene, camera);
  }
  window.addEventListener('resize', () => { resize(); render(); });

  // ---- frame state ----
  let current = 0;
  const slider = el('slider');
  slider.max = String(frames.length - 1);
  const cameraSelect = el('camera');
  data.overlayCameras.forEach((c) => {
    const o = document.createElement('option');
    o.value = c; o.textContent = c;
    cameraSelect.appendChild(o);
  });
  if (!data.overlayCameras.length) cameraSelect.disabled = true;
  const healthByFrame = new Map(data.health.map((r) => [Number(r.frame), r]));

  function nearestSurfaceFrame(f) {
    let best = null;
    for (const s of data.surfaceFrames) if (s <= f) best = s;
    return best === null ? data.surfaceFrames[0] : best;
  }
  function showSurfaces(f) {
    const sf = nearestSurfaceFrame(f);
    for (const kind of surfaceKinds) {
      if (surfaces[kind]) scene.remove(surfaces[kind]);
      surfaces[kind] = null;
      if (el('show-' + kind).checked && sf !== undefined) {
        surfaces[kind] = surfaceMesh(kind, sf);
        if (surfaces[kind]) scene.add(surfaces[kind]);
      }
    }
    const shown = surfaceKinds.some((kind) => el('show-' + kind).checked);
    el('surface-note').textContent = shown && sf !== f ? '(surfaces of frame ' + sf + ': the page keeps ' + data.surfaceFrames.length + ' frames\u2019 surfaces)' : '';
  }
  function setFrame(i) {
    current = Math.max(0, Math.min(frames.length - 1, i | 0));
    const f = frames[current];
    slider.value = String(current);
    pose(current);
    model.visible = el('show-model').checked;
    skeleton.visible = joints.visible = el('show-skeleton').checked;
    showSurfaces(f);
    render();
    const h = healthByFrame.get(f);
    el('frame-label').textContent = 'frame ' + f + (f === data.t0 ? ' (reference)' : '') +
      (h ? ' \u00b7 IoU worst ' + h.iou_worst + ' (' + h.iou_worst_camera + ')' + (h.flags ? ' \u00b7 ' + h.flags : '') : '');
    // A camera's name is one path segment, percent-encoded: '#', '?', '%' and '..' in a
    // name never change which file is linked.
    if (data.overlayCameras.length) el('overlay').src = '../export/overlays/' + encodeURIComponent(cameraSelect.value) + '/' + pad(f) + '.png';
    if (data.contact) el('contact').src = '../export/contact_sheets/' + pad(f) + '.png';
    document.querySelectorAll('.cursor').forEach((line) => {
      line.setAttribute('x1', line.dataset.x0 * 1 + line.dataset.step * current);
      line.setAttribute('x2', line.dataset.x0 * 1 + line.dataset.step * current);
    });
  }
  slider.addEventListener('input', () => setFrame(Number(slider.value)));
  cameraSelect.addEventListener('change', () => setFrame(current));
  ['show-model', 'show-skeleton', 'show-graphcut', 'show-hull', 'show-tracked'].forEach((id) => el(id).addEventListener('change', () => setFrame(current)));
  let timer = null;
  el('play').addEventListener('click', () => {
    if (timer) { clearInterval(timer); timer = null; el('play').textContent = 'Play'; return; }
    el('play').textContent = 'Pause';
    timer = setInterval(() => setFrame((current + 1) % frames.length), 120);
  });
  document.addEventListener('keydown', (ev) => {
    if (ev.key === 'ArrowRight') setFrame(current + 1);
    if (ev.key === 'ArrowLeft') setFrame(current - 1);
  });

  // ---- summary, plots, tables ----
  const s = data.summary;
  const statuses = {};
  data.health.forEach((r) => { statuses[r.status] = (statuses[r.status] || 0) + 1; });
  el('summary').innerHTML = '';
  [
    s.frames + ' frames (' + frames[0] + '..' + frames[frames.length - 1] + '), reference frame ' + data.t0,
    s.cameras + ' cameras',
    Object.entries(statuses).map(([k, v]) => v + ' ' + k).join(', '),
    s.flagged + ' flagged, ' + s.recovered + ' needed recovery',
    'pipeline file ' + s.pipeline + ', outputs in ' + s.output,
  ].forEach((t) => { const span = document.createElement('span'); span.textContent = t; el('summary').appendChild(span); });

  function plot(title, series, opts) {
    const W = 1000, H = 170, L = 50, R = 10, T = 10, B = 22;
    const n = frames.length;
    const step = n > 1 ? (W - L - R) / (n - 1) : 0;
    const values = series.flatMap((x) => x.values).filter((v) => Number.isFinite(v));
    let lo = opts.min !== undefined ? opts.min : Math.min(...values);
    let hi = Math.max(...values, lo + 1e-6);
    if (!values.length) { lo = 0; hi = 1; }
    const y = (v) => T + (H - T - B) * (1 - (v - lo) / (hi - lo));
    const svg = document.createElementNS(svgNS, 'svg');
    svg.setAttribute('viewBox', '0 0 ' + W + ' ' + H);
    svg.setAttribute('preserveAspectRatio', 'none');
    const add = (tag, attrs, text) => {
      const e = document.createElementNS(svgNS, tag);
      for (const [k, v] of Object.entries(attrs)) e.setAttribute(k, v);
      if (text !== undefined) e.textContent = text;
      svg.appendChild(e);
      return e;
    };
    add('text', { x: 4, y: y(hi) + 4, 'font-size': 11 }, hi.toFixed(opts.digits));
    add('text', { x: 4, y: y(lo), 'font-size': 11 }, lo.toFixed(opts.digits));
    add('line', { x1: L, x2: W - R, y1: y(lo), y2: y(lo), stroke: '#999' });
    series.forEach((ser) => {
      const pts = ser.values.map((v, i) => Number.isFinite(v) ? (L + step * i) + ',' + y(v) : null).filter(Boolean).join(' ');
      add('polyline', { points: pts, fill: 'none', stroke: ser.colour, 'stroke-width': 2 });
    });
    frames.forEach((f, i) => {
      const h = healthByFrame.get(f);
      if (h && h.flags) add('path', { d: 'M' + (L + step * i) + ',' + (H - B + 2) + 'l-5,9h10z', fill: '#d33' }).appendChild(document.createElementNS(svgNS, 'title')).textContent = 'frame ' + f + ': ' + h.flags;
      if (h && h.recovery) add('circle', { cx: L + step * i, cy: T + 4, r: 4, fill: '#f90' }).appendChild(document.createElementNS(svgNS, 'title')).textContent = 'frame ' + f + ' recovery: ' + h.recovery;
    });
    frames.forEach((f, i) => {
      const hit = add('rect', { x: L + step * (i - 0.5), y: 0, width: Math.max(step, 2), height: H, fill: 'transparent' });
      hit.style.cursor = 'pointer';
      const tip = document.createElementNS(svgNS, 'title');
      tip.textContent = 'frame ' + f + '\n' + opts.tip(i);
      hit.appendChild(tip);
      hit.addEventListener('click', () => setFrame(i));
    });
    const cursor = add('line', { class: 'cursor', y1: 0, y2: H, stroke: '#333', 'stroke-dasharray': '4 3' });
    cursor.dataset.x0 = L; cursor.dataset.step = step;
    const h3 = document.createElement('h3');
    h3.textContent = title + ' ' + series.map((x) => '\u25a0 ' + x.name).join('  ');
    el('plots').appendChild(h3);
    el('plots').appendChild(svg);
  }
  const col = (name) => frames.map((f) => { const h = healthByFrame.get(f); return h && h[name] !== '' ? Number(h[name]) : NaN; });
  const ious = (i) => data.cameras.map((c, k) => c + ' ' + data.iou[i][k].toFixed(3)).join('\n');
  plot('Silhouette IoU of the posed model (hover: every camera)', [
    { name: 'worst camera', values: col('iou_worst'), colour: '#c0392b' },
    { name: 'median', values: col('iou_median'), colour: '#2c7fb8' },
  ], { digits: 2, tip: ious });
  plot('Largest joint motion since the previous tracked frame, m', [
    { name: 'joint motion', values: col('joint_motion_m'), colour: '#555' },
  ], { min: 0, digits: 2, tip: (i) => 'joint motion ' + col('joint_motion_m')[i] + ' m' });
  if (col('unexplained_cm2').some(Number.isFinite)) {
    plot('Unexplained observed surface, cm\u00b2', [
      { name: 'unexplained', values: col('unexplained_cm2'), colour: '#8e44ad' },
    ], { min: 0, digits: 0, tip: (i) => col('unexplained_cm2')[i] + ' cm\u00b2' });
  }
  data.tables.forEach((t) => {
    const h3 = document.createElement('h3');
    h3.textContent = t.title + ' (' + t.file + ')';
    const table = document.createElement('table');
    const head = table.insertRow();
    t.header.forEach((c) => { const th = document.createElement('th'); th.textContent = c; head.appendChild(th); });
    t.rows.forEach((r) => { const tr = table.insertRow(); r.forEach((c) => { tr.insertCell().textContent = c; }); });
    el('tables').appendChild(h3);
    el('tables').appendChild(table);
  });
  el('params').textContent = data.params;

  resize();
  setFrame(Math.max(0, frames.indexOf(data.t0)));

  // For tests and scripts: drive the page and read what it drew.
  window.hullposeReport = {
    webgl: renderer !== null,
    frames: frames,
    setFrame: setFrame,
    current: () => current,
    overlaySrc: () => el('overlay').getAttribute('src'),
    // The surfaces in the 3D view now: 'graphcut', 'hull', 'tracked'.
    shownSurfaces: () => surfaceKinds.filter((kind) => surfaces[kind] !== null),
    // The model's vertices projected into the canvas, CSS pixels (every k-th).
    modelScreenPoints: (k) => {
      const out = [];
      if (!renderer) return out;
      const v = new THREE.Vector3();
      const rect = renderer.domElement.getBoundingClientRect();
      for (let i = 0; i < nv; i += k || 1) {
        v.set(posed[3 * i], posed[3 * i + 1], posed[3 * i + 2]).project(camera);
        out.push([(v.x + 1) / 2 * rect.width, (1 - v.y) / 2 * rect.height]);
      }
      return out;
    },
    // The share of `points` (CSS pixels) whose pixel differs from the background.
    drawnShare: (points) => {
      if (!renderer) return 0;
      const c = renderer.domElement;
      const scratch = document.createElement('canvas');
      scratch.width = c.width; scratch.height = c.height;
      const g = scratch.getContext('2d');
      g.drawImage(c, 0, 0);
      const img = g.getImageData(0, 0, c.width, c.height).data;
      const ratio = c.width / c.getBoundingClientRect().width;
      const bg = [(CLEAR >> 16) & 255, (CLEAR >> 8) & 255, CLEAR & 255];
      let drawn = 0, inside = 0;
      for (const [x, y] of points) {
        const px = Math.round(x * ratio), py = Math.round(y * ratio);
        if (px < 0 || py < 0 || px >= c.width || py >= c.height) continue;
        inside++;
        const o = 4 * (py * c.width + px);
        const d = Math.abs(img[o] - bg[0]) + Math.abs(img[o + 1] - bg[1]) + Math.abs(img[o + 2] - bg[2]);
        if (d > 30) drawn++;
      }
      return inside ? drawn / inside : 0;
    },
  };
  document.body.dataset.ready = 'yes';
})();
