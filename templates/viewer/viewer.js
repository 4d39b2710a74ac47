// The interactive 3D and plan viewer of one evaluation (loceval issues 24 and 38).
//
// Mounted on every `.loceval-viewer[data-scene]` element, it reads its scene (the JSON that
// exporters/viewer/scene.py writes, in a JSON script element with the id the
// root's data-scene names) and draws it with the vendored three.js (globalThis.LOCEVAL_THREE,
// set by the inlined templates/vendor/three build). It makes no request of its own.
//
// State a test (or a user script) can read from the root element:
//   data-ready="true"  once the first frame with every path is drawn;
//   data-time-s        seconds since the reference's first stamp at the timeline's position;
//   data-errors        JSON: estimate name -> its ATE in metres there (absent where it has none);
//   data-tolerance-m   the tolerance's distance in metres (absent without a tolerance);
//   data-verdicts      JSON: estimate name -> "pass", "fail", "undecided" or "none";
//   data-beyond        JSON list of the stretches beyond the tolerance, worst first:
//                      {estimate, t0_s, t1_s (the timeline's seconds), space (or null)}.
// The scale bar (.lv-scale, plan view) carries data-scale-m (the length it stands for) and
// data-scale-px (its drawn length in CSS pixels at the current zoom).
// root.locevalViewer exposes project(pathIndex) (CSS pixel positions of a path's display
// vertices in the canvas), projectXYZ(xyz), setView("plan" | "orbit"), setTimeIndex(i),
// showPath(i, on), showUncertainty(on), reset() (frame the building and the paths),
// fitPaths() (the paths alone) and focusStretch(k) (the k-th of data-beyond).
(function () {
  "use strict";

  const PICK_RADIUS_PX = 8;
  const POINT_SIZE_PX = 4;
  const MARKER_SIZE_PX = 14;
  const PLAY_SECONDS = 20; // a whole recording plays in this long (at least real time / 60)
  const SCALE_TARGET_PX = 110; // the scale bar is the 1-2-5 length nearest this long
  const GRID_LINES = 8; // about this many grid lines across the view
  const LABEL_GAP_PX = 6;

  function el(tag, props, ...children) {
    const node = document.createElement(tag);
    for (const [key, value] of Object.entries(props || {})) {
      if (key === "text") node.textContent = value;
      else if (key === "className") node.className = value;
      else if (key === "style") node.style.cssText = value;
      else if (key.startsWith("on")) node.addEventListener(key.slice(2), value);
      else node.setAttribute(key, value);
    }
    for (const child of children) if (child) node.append(child);
    return node;
  }

  function fmt(value, digits) {
    return Number.isFinite(value) ? value.toFixed(digits) : "—";
  }

  // the 1-2-5 value nearest above value / 2 .. value (a grid step, a scale length)
  function niceStep(value) {
    if (!(value > 0) || !Number.isFinite(value)) return 1;
    const power = Math.pow(10, Math.floor(Math.log10(value)));
    for (const m of [5, 2, 1]) if (m * power <= value) return m * power;
    return power;
  }

  // the digits that print every multiple of step exactly (0.25 -> 2, 500 -> 0)
  function stepDigits(step) {
    for (let d = 0; d < 8; d++) if (Math.abs(Math.round(step * 10 ** d) - step * 10 ** d) < 1e-6) return d;
    return 8;
  }

  // index of the last element of a sorted array <= value (-1 when none)
  function floorIndex(sorted, value) {
    let lo = 0;
    let hi = sorted.length - 1;
    if (hi < 0 || value < sorted[0]) return -1;
    while (lo < hi) {
      const mid = (lo + hi + 1) >> 1;
      if (sorted[mid] <= value) lo = mid; else hi = mid - 1;
    }
    return lo;
  }

  function binColor(bins, error) {
    for (const b of bins) if (b.high === null || error <= b.high) return b.color;
    return bins.length ? bins[bins.length - 1].color : "#000000";
  }

  const BADGES = { pass: "PASS", fail: "FAIL", undecided: "UNDECIDED", none: "NO VERDICT" };

  function mount(root, THREE) {
    const scene = JSON.parse(document.getElementById(root.dataset.scene).textContent);
    const paths = scene.paths;
    const reference = paths[0];
    const base = scene.base;
    const units = scene.units;
    const perMetre = scene.per_metre || 1;
    const coordDigits = Number.isInteger(scene.coordinate_decimals) ? scene.coordinate_decimals : 3;
    const lengths = scene.lengths || { symbol: "m", per_metre: 1, decimals: 3 };
    const length = (m) => (Number.isFinite(m) ? `${(m * lengths.per_metre).toFixed(lengths.decimals)} ${lengths.symbol}` : "—");
    const coord = (v) => fmt(v, coordDigits);
    const verdicts = scene.verdicts || [];
    const beyond = scene.beyond || [];
    THREE.ColorManagement.enabled = false; // the palette's sRGB values reach the screen as they are

    // --- the contract on the root ------------------------------------------------------
    if (scene.tolerance) root.dataset.toleranceM = String(scene.tolerance.distance_m);
    else delete root.dataset.toleranceM;
    root.dataset.verdicts = JSON.stringify(Object.fromEntries(verdicts.map((v) => [v.name, v.status])));
    root.dataset.beyond = JSON.stringify(beyond.map((b) => ({ estimate: b.estimate, t0_s: b.t0_s, t1_s: b.t1_s, space: b.space })));

    // --- the DOM -------------------------------------------------------------------------
    root.replaceChildren();
    const head = el("div", { className: "lv-head" });
    for (const v of verdicts) {
      const path = paths.find((p) => p.name === v.name);
      head.append(el("div", { className: `lv-verdict lv-${v.status}`, "data-estimate": v.name },
        el("span", { className: `lv-badge lv-badge-${v.status}`, text: BADGES[v.status] || v.status }),
        el("span", { className: "lv-swatch", style: `background:${path ? path.color : "#888"}` }),
        el("strong", { text: v.name }), ` ${v.text}`));
    }
    if (scene.legend) head.append(el("div", { className: "lv-tolerance", text: scene.legend }));
    for (const w of scene.building_warnings || []) head.append(el("div", { className: "lv-warning", role: "note", text: w }));
    const viewButtons = {
      plan: el("button", { type: "button", "data-view": "plan", text: "Plan", title: "Top view" }),
      orbit: el("button", { type: "button", "data-view": "orbit", text: "3D", title: "Orbit: drag to turn, shift-drag or right-drag to pan, wheel to zoom" }),
    };
    const resetButton = el("button", { type: "button", "data-action": "reset", text: "Fit all", title: "Frame the building and the paths" });
    const pathsButton = el("button", { type: "button", "data-action": "fit-paths", text: "Fit paths", title: "Frame the paths alone" });
    const toggles = el("div", { className: "lv-group lv-paths" });
    const controls = scene.controls || null; // an evaluation against control points
    const legend = el("div", { className: "lv-legend", "aria-label": "ATE colour scale" },
      el("span", { text: controls ? "Error at control points:" : "ATE:" }));
    for (const b of scene.bins) {
      legend.append(el("span", { className: b.beyond ? "lv-bin lv-bin-beyond" : "lv-bin" },
        el("span", { className: "lv-swatch", style: `background:${b.color}` }), ` ${b.label}`));
    }
    const bar = el("div", { className: "lv-bar" },
      el("div", { className: "lv-group" }, viewButtons.plan, viewButtons.orbit, resetButton, pathsButton), toggles, legend);
    const stage = el("div", { className: "lv-stage" });
    const overlay = el("div", { className: "lv-overlay" });
    const tip = el("div", { className: "lv-tip", hidden: "" });
    const scaleLabel = el("span", { className: "lv-scale-label" });
    const scaleBar = el("div", { className: "lv-scale", hidden: "", "aria-label": "scale bar" }, el("span", { className: "lv-scale-line" }), scaleLabel);
    const play = el("button", { type: "button", "data-action": "play", text: "▶ Play", "aria-label": "Play" });
    const slider = el("input", {
      type: "range", min: "0", max: String(Math.max(0, reference.t.length - 1)), step: "1", value: "0",
      "aria-label": "Time since the reference's first stamp",
    });
    const readout = el("output", { className: "lv-readout", "aria-live": "polite" });
    const reduced = paths.filter((p) => p.poses > p.t.length)
      .map((p) => `${p.name} ${p.t.length.toLocaleString("en")} of ${p.poses.toLocaleString("en")}`);
    const info = el("div", {
      className: "lv-info",
      text: `Hover or click a point of a path for its stamp, error and coordinates (coordinates in ${units}, errors in ${lengths.symbol}).` + (reduced.length
        ? ` Drawn: ${reduced.join(", ")} poses (every error peak and break kept); errors.csv has every pose.`
        : ""),
    });
    root.append(head, bar, stage, el("div", { className: "lv-time" }, play, slider, readout), info);
    // The hint is never cut: its line takes the hint's height (again when the width changes),
    // and keeps it for a point's figures shown there later, so they do not resize the view.
    const hint = info.textContent;
    let infoWidth = -1;
    function fitInfo() {
      if (info.clientWidth === infoWidth) return;
      infoWidth = info.clientWidth;
      const shown = info.textContent;
      info.style.height = "";
      info.textContent = hint;
      const needed = info.scrollHeight + (info.offsetHeight - info.clientHeight);
      info.textContent = shown;
      info.style.height = `${Math.max(needed, info.offsetHeight)}px`;
    }
    fitInfo();
    new ResizeObserver(fitInfo).observe(root);
    if (beyond.length) drawStretchList();

    // --- three.js ----------------------------------------------------------------------
    let renderer;
    try {
      // asked first, so a browser without WebGL gets the note, not three.js's console error
      const probe = document.createElement("canvas");
      if (!(probe.getContext("webgl2") || probe.getContext("webgl"))) throw new Error("no WebGL");
      renderer = new THREE.WebGLRenderer({ antialias: false, preserveDrawingBuffer: true });
    } catch (err) {
      stage.append(el("p", { className: "lv-note", text: "This browser cannot draw 3D (WebGL is off or unavailable); the report's figures and errors.csv hold the same data." }));
      root.dataset.ready = "error";
      return;
    }
    renderer.outputColorSpace = THREE.LinearSRGBColorSpace;
    renderer.setPixelRatio(window.devicePixelRatio || 1);
    renderer.setClearColor(0xffffff, 1);
    // Every path, marker and label is drawn in three's transparent pass, like the see-through
    // building, so renderOrder alone decides: building first, then the paths over it.
    stage.append(renderer.domElement, overlay, tip, scaleBar);
    const world = new THREE.Scene();

    // the extent of the paths, and of the building (framed with them unless far larger)
    const pathsBox = new THREE.Box3();
    for (const p of paths) {
      for (let i = 0; i < p.xyz.length; i += 3) pathsBox.expandByPoint(new THREE.Vector3(p.xyz[i], p.xyz[i + 1], p.xyz[i + 2]));
    }
    for (const c of controls ? controls.points : []) pathsBox.expandByPoint(new THREE.Vector3(...c.xyz));
    if (pathsBox.isEmpty()) pathsBox.expandByPoint(new THREE.Vector3(0, 0, 0));
    const building = scene.building;
    const buildingBox = new THREE.Box3();
    if (building && building.kind === "mesh") buildingBox.setFromArray(building.positions);
    else if (building && building.kind === "plan" && building.segments.length) {
      buildingBox.setFromArray(building.segments);
      buildingBox.min.z = pathsBox.min.z; buildingBox.max.z = pathsBox.min.z;
    }
    const allBox = pathsBox.clone();
    const upTo = scene.frame_building_up_to || 20;
    const pathsSpan = Math.max(pathsBox.getSize(new THREE.Vector3()).length(), perMetre);
    if (!buildingBox.isEmpty() && buildingBox.getSize(new THREE.Vector3()).length() <= upTo * pathsSpan) allBox.union(buildingBox);
    const floorZ = building && building.kind === "mesh" ? buildingBox.min.z : pathsBox.min.z;
    const allSize = allBox.getSize(new THREE.Vector3());
    const radius = Math.max(allSize.x, allSize.y, allSize.z, 1e-3) * 0.5;

    const ellipses = []; // filled by drawPath for estimates with covariances
    drawBuilding();
    const grid = { lines: null, key: "" };
    const layers = paths.map(drawPath);
    const anchorLabels = drawAnchors().concat(drawControls());
    const excursions = drawExcursions();
    if (ellipses.length) {
      const box = el("input", { type: "checkbox", "data-action": "uncertainty" });
      box.addEventListener("change", () => showUncertainty(box.checked));
      toggles.append(el("label", { title: "2-sigma ellipses of the covariance the estimate reports" }, box, "Uncertainty (2σ)"));
    }
    function showUncertainty(on) {
      for (const e of ellipses) e.visible = on;
      const box = toggles.querySelector("input[data-action=uncertainty]");
      if (box) box.checked = on;
      requestRender();
    }
    const worstLabels = scene.worst.map((w) => ({
      path: w.path, index: w.index, rank: w.rank || 0, within: Boolean(w.within),
      node: overlay.appendChild(el("div", { className: `lv-label lv-worst${w.within ? " lv-within" : ""}`, text: w.label, title: w.title || w.label })),
    }));
    // the building's named spaces, at their floor's centre (below the paths' labels)
    const spaceLabels = (scene.spaces || []).map((s) => ({
      xyz: s.xyz, node: overlay.appendChild(el("div", { className: "lv-label lv-space", text: s.name })),
    }));
    const axisLabels = [];

    function drawBuilding() {
      const b = scene.building;
      if (b && b.kind === "mesh") {
        const geometry = new THREE.BufferGeometry();
        geometry.setAttribute("position", new THREE.Float32BufferAttribute(b.positions, 3));
        geometry.setIndex(b.index);
        geometry.computeVertexNormals();
        const mesh = new THREE.Mesh(geometry, new THREE.MeshLambertMaterial({
          color: 0x8a9bb0, transparent: true, opacity: 0.2, side: THREE.DoubleSide, depthWrite: false,
        }));
        mesh.name = "building";
        mesh.renderOrder = 0;
        world.add(mesh);
        world.add(new THREE.HemisphereLight(0xffffff, 0x667788, 2.2));
        const sun = new THREE.DirectionalLight(0xffffff, 1.2);
        sun.position.set(1, 0.6, 2);
        world.add(sun);
      } else if (b && b.kind === "plan") {
        const geometry = new THREE.BufferGeometry();
        const z = pathsBox.min.z;
        const xyz = Float32Array.from(b.segments, (v, i) => (i % 3 === 2 ? z : v));
        geometry.setAttribute("position", new THREE.BufferAttribute(xyz, 3));
        const lines = new THREE.LineSegments(geometry, new THREE.LineBasicMaterial({ color: 0x9aa3ad, transparent: true }));
        lines.name = "building";
        lines.renderOrder = 1;
        world.add(lines);
      }
    }

    // the grid on the floor: in plan, lines every 1-2-5 step across the visible area; in 3D,
    // over the framed extent. Rebuilt only when its step or extent changes.
    function updateGrid() {
      let step, x0, x1, y0, y1;
      if (view.mode === "plan") {
        const span = (plan.right - plan.left);
        step = niceStep(span / GRID_LINES);
        x0 = view.target.x + plan.left; x1 = view.target.x + plan.right;
        y0 = view.target.y + plan.bottom; y1 = view.target.y + plan.top;
      } else {
        const c = view.frame.centre; const s = view.frame.size;
        const half = Math.max(s.x, s.y, 1e-3) * 0.6;
        step = niceStep((2 * half) / GRID_LINES);
        x0 = c.x - half; x1 = c.x + half; y0 = c.y - half; y1 = c.y + half;
      }
      // grid lines fall on whole steps of the model's coordinates (local + base)
      const ix0 = Math.floor((x0 + base[0]) / step); const ix1 = Math.ceil((x1 + base[0]) / step);
      const iy0 = Math.floor((y0 + base[1]) / step); const iy1 = Math.ceil((y1 + base[1]) / step);
      const key = `${view.mode}:${step}:${ix0}:${ix1}:${iy0}:${iy1}`;
      grid.step = step;
      grid.xs = []; grid.ys = [];
      for (let i = ix0; i <= ix1 && grid.xs.length < 400; i++) grid.xs.push(i * step - base[0]);
      for (let i = iy0; i <= iy1 && grid.ys.length < 400; i++) grid.ys.push(i * step - base[1]);
      grid.x0 = ix0 * step - base[0]; grid.x1 = ix1 * step - base[0];
      grid.y0 = iy0 * step - base[1]; grid.y1 = iy1 * step - base[1];
      if (key === grid.key) return;
      grid.key = key;
      const xyz = [];
      const z = floorZ;
      for (const x of grid.xs) xyz.push(x, grid.y0, z, x, grid.y1, z);
      for (const y of grid.ys) xyz.push(grid.x0, y, z, grid.x1, y, z);
      if (grid.lines) { world.remove(grid.lines); grid.lines.geometry.dispose(); }
      const g = new THREE.BufferGeometry();
      g.setAttribute("position", new THREE.Float32BufferAttribute(xyz, 3));
      grid.lines = new THREE.LineSegments(g, new THREE.LineBasicMaterial({ color: 0xe3e6eb, transparent: true, depthWrite: false }));
      grid.lines.name = "grid";
      grid.lines.renderOrder = -1;
      world.add(grid.lines);
    }

    function drawPath(p, k) {
      const n = p.t.length;
      const positions = new THREE.Float32BufferAttribute(p.xyz, 3);
      const colors = new Float32Array(n * 3);
      const c = new THREE.Color();
      for (let i = 0; i < n; i++) {
        c.set(p.kind === "estimate" ? binColor(scene.bins, p.err[i]) : p.color);
        colors[3 * i] = c.r; colors[3 * i + 1] = c.g; colors[3 * i + 2] = c.b;
      }
      const breaks = new Set(p.breaks);
      const index = [];
      for (let i = 0; i + 1 < n; i++) if (!breaks.has(i)) index.push(i, i + 1);
      const geometry = new THREE.BufferGeometry();
      geometry.setAttribute("position", positions);
      geometry.setAttribute("color", new THREE.BufferAttribute(colors, 3));
      const pointsGeometry = geometry.clone();
      geometry.setIndex(index);
      const group = new THREE.Group();
      const lines = new THREE.LineSegments(geometry, new THREE.LineBasicMaterial({ vertexColors: true, depthTest: false, transparent: true }));
      const dots = new THREE.Points(pointsGeometry, new THREE.PointsMaterial({ vertexColors: true, size: POINT_SIZE_PX, sizeAttenuation: false, depthTest: false, transparent: true }));
      lines.renderOrder = dots.renderOrder = 10 + 2 * k;
      group.add(lines, dots);
      if (p.uncertainty) group.add(drawEllipses(p));
      group.name = p.name;
      world.add(group);
      const marker = makeMarker(p.color, 20 + k);
      const layer = { group, marker, visible: true, vector: null };
      if (p.kind === "estimate") {
        const g = new THREE.BufferGeometry();
        g.setAttribute("position", new THREE.BufferAttribute(new Float32Array(6), 3));
        layer.vector = new THREE.Line(g, new THREE.LineBasicMaterial({ color: 0x111111, depthTest: false, transparent: true }));
        layer.vector.renderOrder = 30;
        layer.vector.visible = false;
        world.add(layer.vector);
        layer.label = overlay.appendChild(el("div", { className: "lv-label lv-now", hidden: "" }));
      }
      const box = el("input", { type: "checkbox", checked: "", "data-path": String(k) });
      box.addEventListener("change", () => showPath(k, box.checked));
      toggles.append(el("label", { title: p.source || p.name }, box,
        el("span", { className: "lv-swatch", style: `background:${p.color}` }), p.name));
      return layer;
    }

    // 2-sigma ellipses of the reported covariance (scene.py): shown with the Uncertainty box
    function drawEllipses(p) {
      const SEGMENTS = 24;
      const xyz = [];
      const u = p.uncertainty;
      for (let e = 0; e < u.index.length; e++) {
        const i = u.index[e];
        const [a, b, angle] = u.ellipse.slice(3 * e, 3 * e + 3);
        const [cx, cy, cz] = p.xyz.slice(3 * i, 3 * i + 3);
        const ca = Math.cos(angle);
        const sa = Math.sin(angle);
        for (let k = 0; k < SEGMENTS; k++) {
          for (const step of [k, k + 1]) {
            const w = (2 * Math.PI * step) / SEGMENTS;
            const x = a * Math.cos(w);
            const y = b * Math.sin(w);
            xyz.push(cx + ca * x - sa * y, cy + sa * x + ca * y, cz);
          }
        }
      }
      const g = new THREE.BufferGeometry();
      g.setAttribute("position", new THREE.Float32BufferAttribute(xyz, 3));
      const lines = new THREE.LineSegments(g, new THREE.LineBasicMaterial({ color: new THREE.Color(p.color), depthTest: false, transparent: true, opacity: 0.6 }));
      lines.renderOrder = 9;
      lines.visible = false;
      lines.name = "uncertainty";
      ellipses.push(lines);
      return lines;
    }

    // stretches outside the tracked room (scene.py's excursions, the CAD files' selection):
    // a dashed purple line over the estimate's path and its label, with their own box
    function drawExcursions() {
      const list = scene.excursions || [];
      if (!list.length) return [];
      const material = new THREE.LineDashedMaterial({
        color: new THREE.Color(scene.excursion_color), dashSize: radius / 60, gapSize: radius / 120,
        depthTest: false, transparent: true,
      });
      const out = list.map((x) => {
        const g = new THREE.BufferGeometry();
        g.setAttribute("position", new THREE.Float32BufferAttribute(x.xyz, 3));
        const line = new THREE.Line(g, material);
        line.computeLineDistances();
        line.renderOrder = 35;
        line.name = "excursion";
        world.add(line);
        const node = overlay.appendChild(el("div", { className: "lv-label lv-excursion", text: x.label }));
        node.style.color = scene.excursion_color;
        return { path: x.path, xyz: x.xyz, line, node, on: true };
      });
      const box = el("input", { type: "checkbox", checked: "", "data-action": "excursions" });
      box.addEventListener("change", () => {
        for (const x of out) x.on = box.checked;
        requestRender();
      });
      toggles.append(el("label", { title: "Stretches where the reference was lost while the estimate went on" }, box,
        el("span", { className: "lv-swatch", style: `background:${scene.excursion_color}` }), "Outside the tracked room"));
      return out;
    }

    function makeMarker(color, order) {
      const g = new THREE.BufferGeometry();
      g.setAttribute("position", new THREE.BufferAttribute(new Float32Array(3), 3));
      const ring = new THREE.Points(g, new THREE.PointsMaterial({ color: 0x111111, size: MARKER_SIZE_PX, sizeAttenuation: false, depthTest: false, transparent: true }));
      const dot = new THREE.Points(g, new THREE.PointsMaterial({ color: new THREE.Color(color), size: MARKER_SIZE_PX - 5, sizeAttenuation: false, depthTest: false, transparent: true }));
      ring.renderOrder = order + 40;
      dot.renderOrder = order + 41;
      const group = new THREE.Group();
      group.add(ring, dot);
      group.visible = false;
      world.add(group);
      return { group, geometry: g };
    }

    function drawAnchors() {
      if (!scene.anchors.length) return [];
      const xyz = scene.anchors.flatMap((a) => a.xyz);
      const g = new THREE.BufferGeometry();
      g.setAttribute("position", new THREE.Float32BufferAttribute(xyz, 3));
      const dots = new THREE.Points(g, new THREE.PointsMaterial({ color: 0x3b3b98, size: 10, sizeAttenuation: false, depthTest: false, transparent: true }));
      dots.renderOrder = 50;
      dots.name = "anchors";
      world.add(dots);
      return scene.anchors.map((a) => ({ xyz: a.xyz, node: overlay.appendChild(el("div", { className: "lv-label", text: `anchor ${a.id}` })) }));
    }

    // control points (white dots, black rings, their ids) and each visit's error vector from
    // the surveyed point to the measured position, coloured by its error (grey: alignment)
    function drawControls() {
      if (!controls) return [];
      const g = new THREE.BufferGeometry();
      g.setAttribute("position", new THREE.Float32BufferAttribute(controls.points.flatMap((c) => c.xyz), 3));
      const ring = new THREE.Points(g, new THREE.PointsMaterial({ color: 0x111111, size: 11, sizeAttenuation: false, depthTest: false, transparent: true }));
      const fill = new THREE.Points(g, new THREE.PointsMaterial({ color: 0xffffff, size: 7, sizeAttenuation: false, depthTest: false, transparent: true }));
      ring.renderOrder = 60; fill.renderOrder = 61;
      const ends = [];
      const colours = [];
      const c = new THREE.Color();
      for (const v of controls.visits) {
        ends.push(...v.surveyed, ...v.measured);
        c.set(v.color);
        colours.push(c.r, c.g, c.b, c.r, c.g, c.b);
      }
      const lg = new THREE.BufferGeometry();
      lg.setAttribute("position", new THREE.Float32BufferAttribute(ends, 3));
      lg.setAttribute("color", new THREE.Float32BufferAttribute(colours, 3));
      const vectors = new THREE.LineSegments(lg, new THREE.LineBasicMaterial({ vertexColors: true, depthTest: false, transparent: true }));
      const measured = new THREE.Points(lg, new THREE.PointsMaterial({ vertexColors: true, size: 6, sizeAttenuation: false, depthTest: false, transparent: true }));
      vectors.renderOrder = 62; measured.renderOrder = 63;
      const group = new THREE.Group();
      group.name = "control points";
      group.add(vectors, measured, ring, fill);
      world.add(group);
      return controls.points.map((p) => {
        const errors = controls.visits.filter((v) => v.id === p.id && !v.alignment).map((v) => v.error);
        const text = errors.length ? `${p.id} ${length(Math.max(...errors))}` : p.id;
        return { xyz: p.xyz, node: overlay.appendChild(el("div", { className: "lv-label", text })) };
      });
    }

    // the stretches beyond the tolerance as a list: a click moves the timeline and the view there
    function drawStretchList() {
      const list = el("ol", { className: "lv-beyond-list" });
      beyond.forEach((b, k) => {
        const multi = verdicts.length > 1 ? `${b.estimate} ` : "";
        const button = el("button", { type: "button", "data-stretch": String(k), title: "Show this stretch" },
          el("span", { className: "lv-rank", text: `#${b.rank}` }), ` ${multi}${b.text}`);
        button.addEventListener("click", () => focusStretch(k));
        list.append(el("li", {}, button));
      });
      const total = scene.beyond_total || beyond.length;
      const count = total === 1 ? "1 stretch" : `${total.toLocaleString("en")} stretches`;
      const shown = total > beyond.length ? ` (the ${beyond.length} worst listed; result.json has all)` : "";
      const details = el("details", { className: "lv-beyond", open: "" },
        el("summary", { text: `Beyond the tolerance: ${count}, worst first${shown}` }), list);
      root.append(details);
      return details;
    }

    // --- cameras and the two views -----------------------------------------------------
    const plan = new THREE.OrthographicCamera(-1, 1, 1, -1, -1e7, 1e7);
    const orbit = new THREE.PerspectiveCamera(45, 1, radius / 1000, radius * 1000);
    orbit.up.set(0, 0, 1);
    const view = {
      mode: "plan", target: new THREE.Vector3(), zoom: 1, azimuth: -Math.PI / 2, elevation: 0.7, distance: 1,
      frame: { centre: allBox.getCenter(new THREE.Vector3()), size: allSize.clone() },
    };
    let camera = plan;

    function aspect() {
      const r = stage.getBoundingClientRect();
      return Math.max(r.width, 1) / Math.max(r.height, 1);
    }

    function updateCamera() {
      const a = aspect();
      const s = view.frame.size;
      if (view.mode === "plan") {
        const half = Math.max(s.y / 2, s.x / 2 / a, radius * 0.02, 1e-3) * 1.12 / view.zoom;
        plan.left = -half * a; plan.right = half * a; plan.top = half; plan.bottom = -half;
        plan.position.set(view.target.x, view.target.y, allBox.max.z + radius * 10 + 1);
        plan.up.set(0, 1, 0);
        plan.lookAt(view.target.x, view.target.y, view.target.z);
        plan.updateProjectionMatrix();
        camera = plan;
      } else {
        orbit.aspect = a;
        const ce = Math.cos(view.elevation);
        orbit.position.set(
          view.target.x + view.distance * ce * Math.cos(view.azimuth),
          view.target.y + view.distance * ce * Math.sin(view.azimuth),
          view.target.z + view.distance * Math.sin(view.elevation));
        orbit.lookAt(view.target);
        orbit.updateProjectionMatrix();
        camera = orbit;
      }
      camera.updateMatrixWorld();
    }

    function frameBox(box) {
      const size = box.getSize(new THREE.Vector3());
      view.frame = { centre: box.getCenter(new THREE.Vector3()), size };
      view.target.copy(view.frame.centre);
      view.zoom = 1;
      view.distance = Math.max(size.x, size.y, size.z, 1e-3) * 1.4 + 1e-3;
      requestRender();
    }

    function reset() {
      view.azimuth = -Math.PI / 2;
      view.elevation = 0.7;
      frameBox(allBox);
    }

    function fitPaths() {
      frameBox(pathsBox);
    }

    function setView(mode) {
      view.mode = mode;
      for (const [name, button] of Object.entries(viewButtons)) button.setAttribute("aria-pressed", String(name === mode));
      requestRender();
    }
    viewButtons.plan.addEventListener("click", () => setView("plan"));
    viewButtons.orbit.addEventListener("click", () => setView("orbit"));
    resetButton.addEventListener("click", reset);
    pathsButton.addEventListener("click", fitPaths);

    // a stretch beyond the tolerance: the timeline to its start, the view around it
    function focusStretch(k) {
      const b = beyond[k];
      if (!b) return;
      const p = paths[b.path];
      const box = new THREE.Box3();
      for (let i = b.i0; i <= b.i1; i++) box.expandByPoint(new THREE.Vector3(p.xyz[3 * i], p.xyz[3 * i + 1], p.xyz[3 * i + 2]));
      const least = Math.max(allSize.x, allSize.y) * 0.2; // never closer than a fifth of the whole
      box.expandByVector(new THREE.Vector3(least, least, 0).sub(box.getSize(new THREE.Vector3())).max(new THREE.Vector3()).multiplyScalar(0.5));
      frameBox(box);
      setTimeIndex(Math.max(0, floorIndex(reference.t, b.t0_s)));
      for (const button of root.querySelectorAll(".lv-beyond button")) button.setAttribute("aria-current", String(button.dataset.stretch === String(k)));
      info.textContent = `${b.estimate} #${b.rank}: ${b.text}`;
      info.dataset.stretch = String(k);
    }

    // --- pointer: drag to pan/turn, wheel to zoom, hover/click to read a point ----------
    let drag = null;
    const canvas = renderer.domElement;
    canvas.addEventListener("contextmenu", (e) => e.preventDefault());
    canvas.addEventListener("pointerdown", (e) => {
      drag = { x: e.clientX, y: e.clientY, moved: false, pan: view.mode === "plan" || e.shiftKey || e.button === 2 };
      canvas.setPointerCapture(e.pointerId);
    });
    canvas.addEventListener("pointermove", (e) => {
      if (!drag) { hover(e); return; }
      const dx = e.clientX - drag.x;
      const dy = e.clientY - drag.y;
      if (!drag.moved && Math.hypot(dx, dy) < 4) return;
      drag.moved = true;
      drag.x = e.clientX; drag.y = e.clientY;
      const r = stage.getBoundingClientRect();
      if (drag.pan) {
        const perPx = view.mode === "plan"
          ? (plan.top - plan.bottom) / Math.max(r.height, 1)
          : 2 * view.distance * Math.tan((orbit.fov * Math.PI) / 360) / Math.max(r.height, 1);
        const right = new THREE.Vector3().setFromMatrixColumn(camera.matrixWorld, 0);
        const up = new THREE.Vector3().setFromMatrixColumn(camera.matrixWorld, 1);
        view.target.addScaledVector(right, -dx * perPx).addScaledVector(up, dy * perPx);
      } else {
        view.azimuth -= dx * 0.008;
        view.elevation = Math.min(1.55, Math.max(-1.55, view.elevation + dy * 0.008));
      }
      requestRender();
    });
    canvas.addEventListener("pointerup", (e) => {
      if (drag && !drag.moved) select(e);
      drag = null;
    });
    canvas.addEventListener("pointerleave", () => { tip.hidden = true; });
    canvas.addEventListener("wheel", (e) => {
      e.preventDefault();
      const f = Math.exp(-e.deltaY * 0.0015);
      if (view.mode === "plan") view.zoom *= f; else view.distance /= f;
      requestRender();
    }, { passive: false });

    function pick(e) {
      const r = canvas.getBoundingClientRect();
      const x = e.clientX - r.left;
      const y = e.clientY - r.top;
      let best = null;
      let bestD = PICK_RADIUS_PX * PICK_RADIUS_PX;
      for (let k = paths.length - 1; k >= 0; k--) {
        if (!layers[k].visible) continue;
        const screen = project(k);
        for (let i = 0; i < screen.length; i++) {
          const d = (screen[i][0] - x) ** 2 + (screen[i][1] - y) ** 2;
          if (d < bestD) { bestD = d; best = { k, i }; }
        }
      }
      return best ? { ...best, x, y } : null;
    }

    function describe(k, i) {
      const p = paths[k];
      const at = (j) => p.xyz[3 * i + j] + base[j];
      const lines = [`${p.name}`, `t = ${fmt(p.t[i], 3)} s`];
      if (p.kind === "estimate") lines.push(`ATE = ${length(p.err[i])}`);
      lines.push(`x = ${coord(at(0))} ${units}, y = ${coord(at(1))} ${units}, z = ${coord(at(2))} ${units}`);
      return lines;
    }

    function hover(e) {
      const hit = pick(e);
      if (!hit) { tip.hidden = true; return; }
      tip.textContent = describe(hit.k, hit.i).join("\n");
      const r = stage.getBoundingClientRect();
      tip.hidden = false;
      // kept inside the stage: flipped to the left or up near an edge
      const w = tip.offsetWidth; const h = tip.offsetHeight;
      tip.style.left = `${hit.x + 12 + w > r.width ? Math.max(0, hit.x - 12 - w) : hit.x + 12}px`;
      tip.style.top = `${hit.y + 12 + h > r.height ? Math.max(0, hit.y - 12 - h) : hit.y + 12}px`;
    }

    function select(e) {
      const hit = pick(e);
      if (!hit) return;
      const p = paths[hit.k];
      info.textContent = describe(hit.k, hit.i).join(" · ");
      info.dataset.path = p.name;
      info.dataset.tS = String(p.t[hit.i]);
      if (p.kind === "estimate") info.dataset.errorM = String(p.err[hit.i]); else delete info.dataset.errorM;
    }

    // --- visibility --------------------------------------------------------------------
    function showPath(k, on) {
      layers[k].visible = on;
      layers[k].group.visible = on;
      const box = toggles.querySelector(`input[data-path="${k}"]`);
      if (box) box.checked = on;
      setTimeIndex(Number(slider.value));
    }

    // --- the timeline ------------------------------------------------------------------
    function estimateIndexAt(p, t) {
      const n = p.t.length;
      if (!n || t < p.t[0] || t > p.t[n - 1]) return -1;
      const j = floorIndex(p.t, t);
      if (j === n - 1 || p.t[j] === t) return j;
      if (p.breaks.includes(j)) return -1; // inside a tracking loss: no estimate there
      return t - p.t[j] <= p.t[j + 1] - t ? j : j + 1;
    }

    function setMarker(marker, xyz, i, show) {
      marker.group.visible = show;
      if (!show) return;
      marker.geometry.attributes.position.array.set([xyz[3 * i], xyz[3 * i + 1], xyz[3 * i + 2]]);
      marker.geometry.attributes.position.needsUpdate = true;
    }

    const now = { t: 0, estimates: [] };
    function setTimeIndex(i) {
      i = Math.max(0, Math.min(reference.t.length - 1, Math.round(i)));
      slider.value = String(i);
      const t = reference.t[i];
      const errors = {};
      const parts = [`t = ${fmt(t, 3)} s`];
      now.t = t;
      now.estimates = [];
      setMarker(layers[0].marker, reference.xyz, i, layers[0].visible);
      for (let k = 1; k < paths.length; k++) {
        const p = paths[k];
        const layer = layers[k];
        const j = estimateIndexAt(p, t);
        const show = j >= 0 && layer.visible;
        setMarker(layer.marker, p.xyz, j, show);
        if (p.kind !== "estimate") continue; // a track: its marker only
        layer.vector.visible = show;
        layer.label.hidden = !show;
        if (j < 0) continue;
        errors[p.name] = p.err[j];
        if (!show) continue;
        const v = layer.vector.geometry.attributes.position;
        v.array.set([p.xyz[3 * j], p.xyz[3 * j + 1], p.xyz[3 * j + 2], p.ref[3 * j], p.ref[3 * j + 1], p.ref[3 * j + 2]]);
        v.needsUpdate = true;
        layer.vector.geometry.computeBoundingSphere();
        layer.label.textContent = `${p.name}: ${length(p.err[j])} at t = ${fmt(p.t[j], 1)} s`;
        now.estimates.push({ k, j });
        parts.push(`${p.name}: ${length(p.err[j])}`);
      }
      for (const v of controls ? controls.visits : []) {
        if (t < v.t0 || t > v.t1) continue; // the visit in progress, if any
        errors[paths[v.path].name] = v.error;
        parts.push(`${paths[v.path].name} at ${v.id}: ${length(v.error)}`);
      }
      readout.textContent = parts.join(" · ");
      root.dataset.timeS = String(t);
      root.dataset.errors = JSON.stringify(errors);
      requestRender();
    }
    slider.addEventListener("input", () => setTimeIndex(Number(slider.value)));

    let playing = null;
    function togglePlay() {
      if (playing) { cancelAnimationFrame(playing.frame); playing = null; play.textContent = "▶ Play"; return; }
      const ts = reference.t;
      const span = ts[ts.length - 1] - ts[0];
      const rate = span / Math.max(PLAY_SECONDS, span / 60); // recording seconds per real second
      const start = Number(slider.value) >= ts.length - 1 ? ts[0] : ts[Number(slider.value)];
      const began = performance.now();
      play.textContent = "❚❚ Pause";
      const step = (clock) => {
        const t = start + ((clock - began) / 1000) * rate;
        setTimeIndex(Math.max(0, floorIndex(ts, t)));
        if (t >= ts[ts.length - 1]) { playing = null; play.textContent = "▶ Play"; return; }
        playing.frame = requestAnimationFrame(step);
      };
      playing = { frame: requestAnimationFrame(step) };
    }
    play.addEventListener("click", togglePlay);

    // --- drawing -----------------------------------------------------------------------
    function project(k) {
      return projectXYZ(paths[k].xyz);
    }

    // CSS pixel positions in the canvas of a flat [x, y, z, x, y, z, ...] list of local vertices
    function projectXYZ(xyz) {
      updateCamera();
      const r = canvas.getBoundingClientRect();
      const m = new THREE.Matrix4().multiplyMatrices(camera.projectionMatrix, camera.matrixWorldInverse).elements;
      const out = new Array(xyz.length / 3);
      for (let i = 0; i < out.length; i++) {
        const x = xyz[3 * i]; const y = xyz[3 * i + 1]; const z = xyz[3 * i + 2];
        const w = m[3] * x + m[7] * y + m[11] * z + m[15];
        const nx = (m[0] * x + m[4] * y + m[8] * z + m[12]) / w;
        const ny = (m[1] * x + m[5] * y + m[9] * z + m[13]) / w;
        out[i] = [(nx + 1) / 2 * r.width, (1 - ny) / 2 * r.height];
      }
      return out;
    }

    // where a local point falls on the stage, or null behind the camera or far outside it
    function anchorAt(x, y, z, r) {
      const v = new THREE.Vector3(x, y, z).project(camera);
      if (!(v.z < 1) || Math.abs(v.x) > 1.05 || Math.abs(v.y) > 1.05) return null;
      return { x: ((v.x + 1) / 2) * r.width, y: ((1 - v.y) / 2) * r.height };
    }

    // Labels in order of importance: each takes the first place beside its anchor (right,
    // left, above, below) that stays inside the stage and overlaps no label placed before
    // it; a label with no such place is hidden. Nothing overlaps, nothing leaves the frame.
    function layoutLabels(items, r) {
      const placed = [];
      const fits = (b) => placed.every((o) => b.x + b.w + 2 <= o.x || o.x + o.w + 2 <= b.x || b.y + b.h + 1 <= o.y || o.y + o.h + 1 <= b.y);
      for (const item of items) {
        const node = item.node;
        if (!item.at || item.off) { node.style.display = "none"; continue; }
        node.style.display = "";
        node.style.left = "0px"; node.style.top = "0px";
        const w = node.offsetWidth; const h = node.offsetHeight;
        const { x, y } = item.at;
        const g = LABEL_GAP_PX;
        // beside the point, then above and below it, then stacked further up and down
        const spots = item.fixed ? [[item.centre ? x - w / 2 : x, y]] : [[x + g, y - h / 2], [x - g - w, y - h / 2],
          [x - w / 2, y - g - h], [x - w / 2, y + g]];
        if (!item.fixed) {
          for (let k = 1; k <= 3; k++) {
            const up = y - h / 2 - k * (h + 2); const down = y - h / 2 + k * (h + 2);
            spots.push([x + g, up], [x + g, down], [x - g - w, up], [x - g - w, down]);
          }
        }
        let chosen = null;
        for (const [sx, sy] of spots) {
          const b = { x: Math.min(Math.max(sx, 2), r.width - w - 2), y: Math.min(Math.max(sy, 2), r.height - h - 2), w, h };
          if (w + 4 > r.width || h + 4 > r.height) break;
          // a label pushed inside the frame must stay by its point: it may slide sideways
          // by up to its width and up or down by its height, no further
          if (!item.fixed && (Math.abs(b.x - sx) > w || Math.abs(b.y - sy) > h)) continue;
          if (fits(b)) { chosen = b; break; }
        }
        if (!chosen) { node.style.display = "none"; continue; }
        placed.push(chosen);
        node.style.left = `${chosen.x}px`;
        node.style.top = `${chosen.y}px`;
      }
    }

    function axisLabel(k) {
      while (axisLabels.length <= k) axisLabels.push(overlay.appendChild(el("div", { className: "lv-label lv-axis" })));
      return axisLabels[k];
    }

    // axis numbers (plan: along the bottom and left edges; 3D: along two edges of the grid),
    // in the model's units: whole grid steps of local + base
    function axisItems(r) {
      const items = [];
      const digits = stepDigits(grid.step);
      let k = 0;
      const label = (text, at, fixed, centre) => {
        const node = axisLabel(k++);
        node.textContent = text;
        items.push({ node, at, fixed, centre });
      };
      if (view.mode === "plan") {
        const bottom = r.height - 16;
        for (const x of grid.xs) {
          const a = anchorAt(x, view.target.y, floorZ, r);
          if (a && a.x > 30 && a.x < r.width - 30) label(fmt(x + base[0], digits), { x: a.x, y: bottom }, true, true);
        }
        for (const y of grid.ys) {
          const a = anchorAt(view.target.x, y, floorZ, r);
          if (a && a.y > 14 && a.y < r.height - 30) label(fmt(y + base[1], digits), { x: 3, y: a.y - 7 }, true);
        }
      } else { // along the grid's two far edges: behind the paths, seldom off-screen
        const cam = orbit.position;
        const yEdge = Math.abs(cam.y - grid.y0) > Math.abs(cam.y - grid.y1) ? grid.y0 : grid.y1;
        const xEdge = Math.abs(cam.x - grid.x0) > Math.abs(cam.x - grid.x1) ? grid.x0 : grid.x1;
        for (const x of grid.xs) label(fmt(x + base[0], digits), anchorAt(x, yEdge, floorZ, r), false);
        for (const y of grid.ys) label(fmt(y + base[1], digits), anchorAt(xEdge, y, floorZ, r), false);
      }
      for (let j = k; j < axisLabels.length; j++) axisLabels[j].style.display = "none";
      if (items.length) items[0].node.textContent += ` ${units}`; // the first number names the unit
      return items;
    }

    // the scale bar of the plan view: a 1-2-5 length of the model's units, about 110 px long
    function updateScale(r) {
      if (view.mode !== "plan") {
        scaleBar.hidden = true;
        delete scaleBar.dataset.scaleM; delete scaleBar.dataset.scalePx;
        return;
      }
      const pxPerUnit = r.height / (plan.top - plan.bottom);
      const lengthUnits = niceStep(SCALE_TARGET_PX / pxPerUnit);
      const px = lengthUnits * pxPerUnit;
      scaleBar.hidden = false;
      scaleBar.firstChild.style.width = `${px}px`;
      scaleLabel.textContent = `${fmt(lengthUnits, stepDigits(lengthUnits))} ${units}`;
      scaleBar.dataset.scaleM = String(lengthUnits / perMetre);
      scaleBar.dataset.scalePx = String(px);
    }

    let pending = false;
    function requestRender() {
      if (pending) return;
      pending = true;
      requestAnimationFrame(render);
    }

    function render() {
      pending = false;
      const r = stage.getBoundingClientRect();
      if (r.width < 2 || r.height < 2) return; // hidden (a closed section): drawn when shown
      renderer.setSize(r.width, r.height, false);
      updateCamera();
      updateGrid();
      for (const x of excursions) x.line.visible = x.on && layers[x.path].visible;
      renderer.render(world, camera);
      const items = [];
      for (const { k, j } of now.estimates) {
        const p = paths[k];
        items.push({ node: layers[k].label, at: anchorAt(p.xyz[3 * j], p.xyz[3 * j + 1], p.xyz[3 * j + 2], r) });
      }
      // the greatest errors that matter most first (beyond the tolerance; without one, the
      // three greatest), then the stretches outside the tracked room, then the other greatest
      // errors by rank, then the rooms
      const worstItem = (w) => {
        const xyz = paths[w.path].xyz;
        return { node: w.node, off: !layers[w.path].visible, at: anchorAt(xyz[3 * w.index], xyz[3 * w.index + 1], xyz[3 * w.index + 2], r) };
      };
      const major = (w) => (scene.tolerance ? !w.within : w.rank <= 3);
      const ranked = [...worstLabels].sort((a, b) => a.rank - b.rank);
      items.push(...ranked.filter(major).map(worstItem));
      for (const x of excursions) items.push({ node: x.node, off: !x.line.visible, at: anchorAt(x.xyz[0], x.xyz[1], x.xyz[2], r) });
      items.push(...ranked.filter((w) => !major(w)).map(worstItem));
      for (const s of spaceLabels) items.push({ node: s.node, at: anchorAt(s.xyz[0], s.xyz[1], s.xyz[2], r), centre: true });
      for (const a of anchorLabels) items.push({ node: a.node, at: anchorAt(a.xyz[0], a.xyz[1], a.xyz[2], r) });
      items.push(...axisItems(r));
      updateScale(r);
      if (!scaleBar.hidden) { // the scale bar's corner is taken
        const b = scaleBar.getBoundingClientRect();
        items.unshift({ node: { style: {}, offsetWidth: b.width, offsetHeight: b.height }, at: { x: b.left - r.left, y: b.top - r.top }, fixed: true });
      }
      layoutLabels(items, r);
      if (root.dataset.ready !== "true") root.dataset.ready = "true"; // every path is in this frame
    }

    new ResizeObserver(requestRender).observe(stage);
    root.locevalViewer = { project, projectXYZ, showUncertainty, setView, setTimeIndex, showPath, reset, fitPaths, focusStretch };
    setView("plan");
    reset();
    setTimeIndex(0);
    render(); // the first frame now: a frame out of view gets no animation frames
  }

  function mountAll() {
    const THREE = globalThis.LOCEVAL_THREE;
    for (const root of document.querySelectorAll(".loceval-viewer[data-scene]")) {
      if (root.locevalViewer) continue;
      try {
        mount(root, THREE);
      } catch (err) {
        root.dataset.ready = "error";
        root.append(el("p", { className: "lv-note", text: `The viewer could not start: ${err && err.message}` }));
        throw err;
      }
    }
  }

  if (document.readyState === "loading") document.addEventListener("DOMContentLoaded", mountAll);
  else mountAll();
})();
