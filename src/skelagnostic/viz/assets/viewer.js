// skelagnostic motion viewer: plays the clips stored in #skelagnostic-data with three.js.
// Written for skelagnostic.viz.to_html; BSD-3-Clause like the rest of skelagnostic.
(function () {
  "use strict";

  const errors = [];
  window.addEventListener("error", (event) => errors.push(String(event.message)));

  const data = JSON.parse(document.getElementById("skelagnostic-data").textContent);
  const view = document.getElementById("view");
  const $ = (id) => document.getElementById(id);

  // ---- decode the 16-bit positions: value = origin + code * step (metres, y-up)
  function decode(clip) {
    const bytes = Uint8Array.from(atob(clip.positions), (c) => c.charCodeAt(0));
    const codes = new DataView(bytes.buffer);
    const count = bytes.length / 2;
    const out = new Float32Array(count);
    for (let i = 0; i < count; i++) {
      const axis = i % 3;
      out[i] = clip.origin[axis] + codes.getUint16(2 * i, true) * clip.step[axis];
    }
    return out;
  }

  const fov = 40;
  const renderer = new THREE.WebGLRenderer({ antialias: true, preserveDrawingBuffer: true });
  renderer.setPixelRatio(window.devicePixelRatio || 1);
  renderer.setClearColor(0xffffff, 1);
  view.appendChild(renderer.domElement);
  const scene = new THREE.Scene();
  const camera = new THREE.PerspectiveCamera(fov, 1, 0.01, 5000);
  const controls = new THREE.OrbitControls(camera, renderer.domElement);
  controls.enableDamping = false;

  const sphere = new THREE.SphereGeometry(1, 12, 8);
  const cylinder = new THREE.CylinderGeometry(1, 1, 1, 8, 1);
  const white = () => new THREE.MeshBasicMaterial({ color: 0xffffff });

  // ---- one pair of instanced meshes per clip: joints (clip colour), bones (group colours)
  const clips = data.clips.map((clip, index) => {
    const numJoints = clip.joints.length;
    const bones = [];
    clip.parents.forEach((parent, child) => { if (parent >= 0) bones.push([parent, child]); });
    const height = Math.max(0.2, clip.height);
    const jointRadius = Math.max(0.01, 0.024 * height / 1.7);
    const joints = new THREE.InstancedMesh(sphere, white(), numJoints);
    const boneMesh = new THREE.InstancedMesh(cylinder, white(), Math.max(1, bones.length));
    joints.frustumCulled = false;
    boneMesh.frustumCulled = false;
    const colour = new THREE.Color();
    for (let j = 0; j < numJoints; j++) joints.setColorAt(j, colour.set(clip.color));
    bones.forEach(([, child], b) => boneMesh.setColorAt(b, colour.set(clip.groupColors[clip.groups[child]])));
    if (!bones.length) boneMesh.count = 0;
    const group = new THREE.Group();
    group.add(boneMesh, joints);
    scene.add(group);
    const label = document.createElement("div");
    label.className = "clip-label";
    label.textContent = clip.name;
    label.style.color = clip.color;
    view.appendChild(label);
    return {
      index, clip, group, joints, boneMesh, bones, label, numJoints,
      positions: decode(clip), jointRadius, boneRadius: 0.6 * jointRadius,
      frame: -1, visible: true, offset: new THREE.Vector3(),
    };
  });

  // ---- state and controls
  const fps = data.fps;
  const numFrames = Math.floor(data.duration * fps + 1e-6) + 1;
  const state = { time: 0, playing: false, speed: data.speed, loop: data.loop,
                  follow: data.follow, mode: data.mode, drawn: -1 };
  const scrub = $("scrub");
  scrub.max = String(numFrames - 1);
  $("loop").checked = state.loop;
  $("follow").checked = state.follow;
  $("layout").value = state.mode;
  const speedSelect = $("speed");
  if (![...speedSelect.options].some((o) => Number(o.value) === state.speed)) {
    speedSelect.add(new Option(state.speed + "\u00d7", String(state.speed)));
  }
  speedSelect.value = String(state.speed);

  const frameOf = () => Math.min(numFrames - 1, Math.max(0, Math.round(state.time * fps)));
  function setFrame(frame) {
    state.time = Math.min(numFrames - 1, Math.max(0, frame)) / fps;
  }
  function setPlaying(playing) {
    state.playing = playing;
    $("play").innerHTML = playing ? "&#10074;&#10074;" : "&#9654;";
  }
  $("play").addEventListener("click", () => {
    if (!state.playing && frameOf() >= numFrames - 1) state.time = 0;
    setPlaying(!state.playing);
  });
  $("prev").addEventListener("click", () => { setPlaying(false); setFrame(frameOf() - 1); });
  $("next").addEventListener("click", () => { setPlaying(false); setFrame(frameOf() + 1); });
  scrub.addEventListener("input", () => { setPlaying(false); setFrame(Number(scrub.value)); });
  speedSelect.addEventListener("change", () => { state.speed = Number(speedSelect.value); });
  $("loop").addEventListener("change", (e) => { state.loop = e.target.checked; });
  $("follow").addEventListener("change", (e) => { state.follow = e.target.checked; frameView(); });
  $("layout").addEventListener("change", (e) => { state.mode = e.target.value; layout(); frameView(); });
  $("reset").addEventListener("click", () => frameView());
  document.addEventListener("keydown", (event) => {
    const tag = event.target && event.target.tagName;
    if (tag === "INPUT" || tag === "SELECT" || tag === "BUTTON") return;
    if (event.key === " ") { $("play").click(); event.preventDefault(); }
    if (event.key === ",") $("prev").click();
    if (event.key === ".") $("next").click();
    if (event.key === "h") document.body.classList.toggle("bare");
  });

  // ---- legend, timeline marks
  const legend = $("legend");
  clips.forEach((c) => {
    const row = document.createElement("label");
    const box = document.createElement("input");
    box.type = "checkbox";
    box.checked = true;
    box.addEventListener("change", () => { c.visible = box.checked; c.group.visible = box.checked; });
    const swatch = document.createElement("span");
    swatch.className = "swatch";
    swatch.style.background = c.clip.color;
    const groups = document.createElement("span");
    groups.className = "groups";
    [...new Set(c.clip.groups)].forEach((g) => {
      const s = document.createElement("span");
      s.style.background = c.clip.groupColors[g];
      s.title = g.replace("_", " ");
      groups.appendChild(s);
    });
    const name = document.createElement("span");
    name.textContent = c.clip.name;
    const unit = document.createElement("span");
    unit.className = "unit";
    unit.textContent = c.clip.units === "m" ? "m" : c.clip.units + " \u2192 m";
    row.append(box, swatch, groups, name, unit);
    legend.appendChild(row);
  });
  const marks = $("marks");
  const span = Math.max(data.duration, 1e-9);
  clips.forEach((c) => {
    for (const [kind, frames] of [["keyframe", c.clip.keyframes], ["transition", c.clip.transitions]]) {
      for (const f of frames) {
        const mark = document.createElement("span");
        mark.className = "mark " + kind;
        mark.style.left = (100 * (f / c.clip.fps) / span) + "%";
        mark.style.background = c.clip.color;
        mark.style.color = c.clip.color;
        mark.title = c.clip.name + ": " + kind + " at frame " + f;
        mark.dataset.frame = String(Math.round(f / c.clip.fps * fps));
        mark.addEventListener("click", () => { setPlaying(false); setFrame(Number(mark.dataset.frame)); });
        marks.appendChild(mark);
      }
    }
  });

  // ---- layout (side by side / overlaid), floor grid, camera framing
  const clipBoxes = clips.map((c) => {
    const box = new THREE.Box3();
    const p = c.positions;
    const v = new THREE.Vector3();
    for (let i = 0; i < p.length; i += 3) box.expandByPoint(v.set(p[i], p[i + 1], p[i + 2]));
    return box;
  });
  let grid = null;
  function sceneBox() {
    const box = new THREE.Box3();
    clips.forEach((c, k) => {
      if (c.visible) box.union(clipBoxes[k].clone().translate(c.offset));
    });
    return box;
  }
  function layout() {
    clips.forEach((c) => {
      if (state.mode === "side") c.offset.fromArray(c.clip.sideOffset);
      else c.offset.fromArray(c.clip.overlayOffset);
      c.group.position.copy(c.offset);
      c.frame = -1;
    });
    if (grid) { scene.remove(grid); grid.geometry.dispose(); grid.material.dispose(); }
    const box = sceneBox();
    const size = 2 * Math.ceil(Math.max(box.max.x - box.min.x, box.max.z - box.min.z) / 2 + 1);
    grid = new THREE.GridHelper(size, size, 0x90a4ae, 0xcfd8dc);
    grid.position.set(Math.round((box.min.x + box.max.x) / 2), data.floor,
                      Math.round((box.min.z + box.max.z) / 2));
    scene.add(grid);
  }
  // Look across the lanes, from the front-right and a little above.
  const viewDir = (data.laneAxis === 0 ? new THREE.Vector3(0.25, 0.35, 1) : new THREE.Vector3(1, 0.35, -0.25))
    .normalize();
  function rootCentre() {
    const centre = new THREE.Vector3();
    let n = 0;
    clips.forEach((c) => {
      if (!c.visible) return;
      const f = clipFrame(c) * c.numJoints * 3;
      centre.x += c.positions[f] + c.offset.x;
      centre.z += c.positions[f + 2] + c.offset.z;
      n += 1;
    });
    if (n) centre.divideScalar(n);
    centre.y = data.floor + 0.5 * data.height;
    return centre;
  }
  function frameView() {
    // Fit a box (half width across the view, half height) into both fields of view.
    let centre, halfWidth, halfHeight;
    if (state.follow) {
      centre = rootCentre();
      const box = new THREE.Box3();
      clips.forEach((c) => { if (c.visible) box.expandByPoint(poseCentre(c)); });
      const size = box.isEmpty() ? new THREE.Vector3() : box.getSize(new THREE.Vector3());
      halfWidth = 0.5 * Math.max(size.x, size.z) + 0.7 * data.height;
      halfHeight = 1.0 * data.height;
    } else {
      const box = sceneBox();
      centre = box.getCenter(new THREE.Vector3());
      halfWidth = halfHeight = 0.5 * box.getSize(new THREE.Vector3()).length();
    }
    const tanV = Math.tan((fov / 2) * Math.PI / 180);
    const tanH = tanV * camera.aspect;
    const distance = Math.max(0.5, halfHeight / tanV, halfWidth / tanH) * 1.3;
    controls.target.copy(centre);
    camera.position.copy(centre).addScaledVector(viewDir, distance);
    camera.near = Math.max(0.005, distance / 200);
    camera.far = distance * 50 + 100;
    camera.updateProjectionMatrix();
    controls.update();
  }
  function poseCentre(c) {
    const f = clipFrame(c) * c.numJoints * 3;
    return new THREE.Vector3(c.positions[f], 0, c.positions[f + 2]).add(c.offset);
  }

  // ---- drawing
  const clipFrame = (c) => Math.min(c.clip.frames - 1, Math.max(0, Math.round(state.time * c.clip.fps)));
  const m4 = new THREE.Matrix4();
  const q = new THREE.Quaternion();
  const a = new THREE.Vector3(), b = new THREE.Vector3(), d = new THREE.Vector3();
  const s = new THREE.Vector3();
  const yAxis = new THREE.Vector3(0, 1, 0);
  function pose(c) {
    const frame = clipFrame(c);
    if (frame === c.frame) return;
    c.frame = frame;
    const p = c.positions, base = frame * c.numJoints * 3;
    for (let j = 0; j < c.numJoints; j++) {
      a.set(p[base + 3 * j], p[base + 3 * j + 1], p[base + 3 * j + 2]);
      m4.compose(a, q.identity(), s.setScalar(c.jointRadius));
      c.joints.setMatrixAt(j, m4);
    }
    c.bones.forEach(([parent, child], k) => {
      a.set(p[base + 3 * parent], p[base + 3 * parent + 1], p[base + 3 * parent + 2]);
      b.set(p[base + 3 * child], p[base + 3 * child + 1], p[base + 3 * child + 2]);
      d.subVectors(b, a);
      const length = d.length();
      if (length > 1e-7) q.setFromUnitVectors(yAxis, d.divideScalar(length));
      else q.identity();
      s.set(c.boneRadius, length, c.boneRadius);
      m4.compose(a.add(b).multiplyScalar(0.5), q, s);
      c.boneMesh.setMatrixAt(k, m4);
    });
    c.joints.instanceMatrix.needsUpdate = true;
    c.boneMesh.instanceMatrix.needsUpdate = true;
  }
  function worldJoint(c, j, target) {
    const base = clipFrame(c) * c.numJoints * 3 + 3 * j;
    return target.set(c.positions[base], c.positions[base + 1], c.positions[base + 2]).add(c.offset);
  }
  function toScreen(point) {
    const rect = renderer.domElement.getBoundingClientRect();
    const v = point.clone().project(camera);
    return [rect.left + (v.x + 1) / 2 * rect.width, rect.top + (1 - v.y) / 2 * rect.height, v.z];
  }
  function placeLabels() {
    const top = new THREE.Vector3();
    clips.forEach((c) => {
      if (!c.visible) { c.label.hidden = true; return; }
      let high = -Infinity;
      for (let j = 0; j < c.numJoints; j++) high = Math.max(high, worldJoint(c, j, top).y);
      worldJoint(c, 0, top).y = high + 0.06;
      const [x, y, z] = toScreen(top);
      const rect = view.getBoundingClientRect();
      c.label.hidden = z > 1;
      c.label.style.left = (x - rect.left) + "px";
      c.label.style.top = (y - rect.top) + "px";
    });
  }

  function resize() {
    const w = view.clientWidth || 1, h = view.clientHeight || 1;
    renderer.setSize(w, h);
    camera.aspect = w / h;
    camera.updateProjectionMatrix();
  }
  window.addEventListener("resize", resize);

  let last = null;
  const previousTarget = new THREE.Vector3();
  function tick(now) {
    if (last !== null && state.playing) {
      state.time += Math.min(0.25, (now - last) / 1000) * state.speed;
      if (state.time > data.duration) {
        if (state.loop) state.time = 0;
        else { state.time = data.duration; setPlaying(false); }
      }
    }
    last = now;
    clips.forEach(pose);
    if (state.follow) {
      previousTarget.copy(controls.target);
      const centre = rootCentre();
      camera.position.add(centre.clone().sub(previousTarget));
      controls.target.copy(centre);
      controls.update();
    }
    renderer.render(scene, camera);
    placeLabels();
    const frame = frameOf();
    if (document.activeElement !== scrub || state.playing) scrub.value = String(frame);
    $("frame").textContent = "frame " + frame + " / " + (numFrames - 1) + "  " + state.time.toFixed(2) + " s";
    $("info").textContent = fps.toFixed(fps % 1 ? 2 : 0) + " fps \u00b7 grid 1 m";
    state.drawn = frame;
    requestAnimationFrame(tick);
  }

  // ---- joint names on hover
  const tooltip = $("tooltip");
  renderer.domElement.addEventListener("pointermove", (event) => {
    let best = null, bestDistance = 12;
    const v = new THREE.Vector3();
    clips.forEach((c) => {
      if (!c.visible) return;
      for (let j = 0; j < c.numJoints; j++) {
        const [x, y] = toScreen(worldJoint(c, j, v));
        const dist = Math.hypot(x - event.clientX, y - event.clientY);
        if (dist < bestDistance) { bestDistance = dist; best = [c, j]; }
      }
    });
    if (!best) { tooltip.hidden = true; return; }
    const rect = view.getBoundingClientRect();
    tooltip.textContent = best[0].clip.name + ": " + best[0].clip.joints[best[1]];
    tooltip.style.left = (event.clientX - rect.left + 12) + "px";
    tooltip.style.top = (event.clientY - rect.top + 12) + "px";
    tooltip.hidden = false;
  });
  renderer.domElement.addEventListener("pointerleave", () => { tooltip.hidden = true; });

  resize();
  layout();
  clips.forEach(pose);
  frameView();

  // ---- a small API for scripts and tests
  window.skelagnostic = {
    errors,
    numFrames,
    frame: () => frameOf(),
    drawnFrame: () => state.drawn,
    clipFrame: (k) => clipFrame(clips[k]),
    colors: (k) => [clips[k].clip.color, ...Object.values(clips[k].clip.groupColors)],
    // Screen position (CSS pixels, viewport origin) of every joint of clip k as drawn now.
    project: (k) => {
      const v = new THREE.Vector3();
      const out = [];
      for (let j = 0; j < clips[k].numJoints; j++) out.push(toScreen(worldJoint(clips[k], j, v)).slice(0, 2));
      return out;
    },
    // Camera matrices (column-major, as three.js stores them) and the canvas rectangle.
    camera: () => {
      camera.updateMatrixWorld();
      const rect = renderer.domElement.getBoundingClientRect();
      return { view: camera.matrixWorldInverse.toArray(), projection: camera.projectionMatrix.toArray(),
               rect: [rect.left, rect.top, rect.width, rect.height],
               position: camera.position.toArray(), target: controls.target.toArray() };
    },
    offset: (k) => clips[k].offset.toArray(),
    joints: (k) => {
      const v = new THREE.Vector3();
      return clips[k].clip.joints.map((_, j) => worldJoint(clips[k], j, v).toArray());
    },
  };
  requestAnimationFrame(tick);
})();
