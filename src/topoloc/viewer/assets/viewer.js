/* topoloc viewer: the time slider, playback, layers, belief and confidence chart over a folium (Leaflet) map.
   Reads the JSON block #topoloc-data written by topoloc.viewer.page (see ViewerData there). Exposes
   window.topolocViewer for tests and benchmarks: setRow(i), row(), agentLatLng(name), beliefKey(), visible(name),
   and for closed-loop drives (D.drives) selectDrive(key), driveKey(), driveLatLng(), driveText(). */
(function () {
  "use strict";
  const D = JSON.parse(document.getElementById("topoloc-data").textContent);
  const map = window[D.map];
  const roads = D.roads ? window[D.roads] : null;
  const N = D.time.frame.length;
  const el = (tag, attrs, parent) => {
    const e = document.createElement(tag);
    Object.entries(attrs || {}).forEach(([k, v]) => (k === "text" ? (e.textContent = v) : e.setAttribute(k, v)));
    if (parent) parent.appendChild(e);
    return e;
  };
  const svgEl = (tag, attrs, parent) => {
    const e = document.createElementNS("http://www.w3.org/2000/svg", tag);
    Object.entries(attrs || {}).forEach(([k, v]) => e.setAttribute(k, v));
    if (parent) parent.appendChild(e);
    return e;
  };
  /* the last k with arr[k] <= x (arr sorted), -1 if none */
  const last = (arr, x) => {
    let lo = 0, hi = arr.length - 1, k = -1;
    while (lo <= hi) { const m = (lo + hi) >> 1; if (arr[m] <= x) { k = m; lo = m + 1; } else hi = m - 1; }
    return k;
  };
  const pct = (p) => (100 * p).toFixed(p >= 0.1 ? 0 : 1) + " %";
  const heatColor = (p) => `hsl(${Math.round(60 * (1 - Math.min(1, p)))}, 95%, ${Math.round(50 - 15 * Math.min(1, p))}%)`;

  /* ---- the panels ---- */
  const side = el("div", { id: "tl-side" }, document.body);
  el("h1", { text: D.title }, side);
  const status = el("div", { id: "tl-status" }, side);
  const agentBox = el("div", { id: "tl-agents" }, side);
  let beliefBox = null, img = null, textBox = null;
  if (D.belief) { el("h2", { text: "Belief (metric filter): leading roads" }, side); beliefBox = el("ol", { id: "tl-belief" }, side); }
  if (D.images) { el("h2", { text: "Camera" }, side); img = el("img", { id: "tl-image", alt: "camera frame" }, side); }
  if (D.text) textBox = el("div", { id: "tl-text" }, side);
  let drivePick = null, driveBox = null;
  if (D.drives && D.drives.length) {
    el("h2", { text: "Route following (closed loop)" }, side);
    drivePick = el("select", { id: "tl-drive" }, side);
    D.drives.forEach((d, k) => el("option", { value: k, text: d.label }, drivePick));
    driveBox = el("div", { id: "tl-drive-text" }, side);
  }
  (D.notes || []).forEach((n) => el("p", { class: "tl-note", text: n }, side));
  const bottom = el("div", { id: "tl-bottom" }, document.body);
  const controls = el("div", { id: "tl-controls" }, bottom);
  const play = el("button", { id: "tl-play", type: "button", text: "▶" }, controls);
  const slider = el("input", { id: "tl-slider", type: "range", min: 0, max: N - 1, value: 0, step: 1 }, controls);
  const speed = el("select", { id: "tl-speed" }, controls);
  [1, 4, 16].forEach((s) => el("option", { value: s, text: "×" + s }, speed));
  const clock = el("span", { id: "tl-clock" }, controls);
  const chart = el("div", { id: "tl-chart" }, bottom);

  /* ---- map layers ---- */
  const roadLines = {};
  if (roads) roads.eachLayer((l) => { roadLines[l.feature.properties.edge_id] = l.getLatLngs(); });
  const overlays = {};
  if (roads) overlays["roads"] = roads;
  (D.lines || []).forEach((l) => { overlays[l.name] = L.polyline(l.latlngs, { color: l.color, weight: 3, opacity: 0.7 }).addTo(map); });
  let truthMarker = null, truthTrail = null;
  if (D.truth) {
    const g = L.layerGroup().addTo(map);
    L.polyline(D.truth, { color: "#2ca02c", weight: 2, opacity: 0.35, dashArray: "4 4" }).addTo(g);
    truthTrail = L.polyline([], { color: "#2ca02c", weight: 3, opacity: 0.9 }).addTo(g);
    truthMarker = L.circleMarker(D.truth[0], { radius: 8, color: "#000", weight: 1, fillColor: "#2ca02c", fillOpacity: 1 })
      .bindTooltip("true position").addTo(g);
    overlays["true track"] = g;
  }
  let beliefRoads = null, heat = null;
  if (D.belief) {
    heat = L.heatLayer([], { radius: 14, blur: 12, maxZoom: 16, max: 1, minOpacity: 0.3 }).addTo(map);
    overlays["belief: heat"] = heat;
    beliefRoads = L.layerGroup().addTo(map);
    overlays["belief: leading roads"] = beliefRoads;
  }
  const agents = D.agents.map((a) => {
    const g = L.layerGroup().addTo(map);
    const road = L.polyline([], { color: a.color, weight: 7, opacity: 0.45 }).addTo(g);
    const trail = L.polyline([], { color: a.color, weight: 2, opacity: 0.9 }).addTo(g);
    const marker = L.circleMarker([0, 0], { radius: 6, color: "#000", weight: 1, fillColor: a.color, fillOpacity: 0.95 })
      .bindTooltip(a.label);
    const pts = [], count = [];
    (a.pos || []).forEach((p) => { if (p) pts.push(p); count.push(pts.length); });
    overlays[`<span style="color:${a.color}">●</span> ${a.label} (${a.name})`] = g;
    const row = el("div", { class: "tl-agent" }, agentBox);
    el("span", { class: "tl-swatch", style: `background:${a.color}` }, row);
    const label = el("span", { text: a.label }, row);
    const value = el("span", { class: "tl-value" }, row);
    return { a, g, road, trail, marker, pts, count, label, value, shown: null };
  });
  const marks = L.layerGroup().addTo(map);
  (D.marks || []).forEach((m) => {
    const color = m.kind === "start" ? "#444" : m.kind === "oracle" ? "#000" : m.kind === "fail" ? "#d62728"
      : (agents.find((x) => x.a.name === m.name) || { a: { color: "#000" } }).a.color;
    L.circleMarker([m.lat, m.lon], { radius: m.kind === "start" ? 4 : 7, color, weight: 2, fill: m.kind !== "start",
      fillColor: "#fff", fillOpacity: 0.9 }).bindTooltip(m.label).on("click", () => setRow(m.idx)).addTo(marks);
  });
  if (D.marks && D.marks.length) overlays["events: starts, where each became sure, failures"] = marks;
  /* ---- a closed-loop drive: its trace, the vehicle on it, where it stopped ---- */
  let drive = null;
  if (drivePick) {
    const g = L.layerGroup().addTo(map);
    const path = L.polyline([], { color: "#000", weight: 2, opacity: 0.5, dashArray: "3 5" }).addTo(g);
    const trail = L.polyline([], { color: "#000", weight: 3, opacity: 0.85 }).addTo(g);
    const end = L.marker([0, 0], { icon: L.divIcon({ className: "tl-end", html: "✕", iconSize: [16, 16] }) }).bindTooltip("").addTo(g);
    const vehicle = L.circleMarker([0, 0], { radius: 7, color: "#fff", weight: 2, fillColor: "#000", fillOpacity: 1 })
      .bindTooltip("", { permanent: true, direction: "right", className: "tl-command" });
    drive = { g, path, trail, end, vehicle, d: null, shown: null };
    overlays["closed-loop drive (vehicle, trace, end)"] = g;
    drivePick.addEventListener("change", () => selectDrive(+drivePick.value));
  }
  function selectDrive(k) {
    if (!drive) return;
    if (typeof k === "string") k = D.drives.findIndex((d) => d.key === k);
    k = Math.max(0, Math.min(D.drives.length - 1, k));
    drivePick.value = k;
    drive.d = D.drives[k];
    drive.path.setLatLngs(drive.d.pos);
    const ok = drive.d.outcome === "success";
    drive.end.setLatLng(drive.d.end).setTooltipContent(drive.d.label)
      .setIcon(L.divIcon({ className: ok ? "tl-end tl-end-ok" : "tl-end", html: ok ? "✓" : "✕", iconSize: [16, 16] }));
    if (current >= 0) setRow(current);
  }
  L.control.layers(null, overlays, { collapsed: false }).addTo(map);

  /* ---- the confidence chart over metres driven ---- */
  const W = 1000, H = 150, P = 28, dmax = Math.max(1, D.time.driven_m[N - 1]);
  const svg = svgEl("svg", { viewBox: `0 0 ${W} ${H}`, preserveAspectRatio: "none", id: "tl-svg" }, chart);
  const X = (m) => P + ((W - P - 8) * m) / dmax, Y = (c) => H - 16 - (H - 24) * c;
  svgEl("line", { x1: P, x2: W - 8, y1: Y(D.sure), y2: Y(D.sure), class: "tl-sure" }, svg);
  [0, 0.5, 1].forEach((c) => { const t = svgEl("text", { x: 2, y: Y(c) + 4, class: "tl-axis" }, svg); t.textContent = c; });
  const xl = svgEl("text", { x: W - 8, y: H - 2, class: "tl-axis", "text-anchor": "end" }, svg);
  xl.textContent = `confidence over metres driven (${dmax.toFixed(0)} m); dashed: sure (${D.sure})`;
  agents.forEach((s) => {
    const step = Math.max(1, Math.floor(s.a.idx.length / 1500));
    const pts = [];
    for (let k = 0; k < s.a.idx.length; k += step) pts.push(`${X(D.time.driven_m[s.a.idx[k]]).toFixed(1)},${Y(s.a.conf[k]).toFixed(1)}`);
    s.curve = svgEl("polyline", { points: pts.join(" "), stroke: s.a.color, class: "tl-curve" }, svg);
  });
  (D.marks || []).filter((m) => m.kind === "sure" || m.kind === "oracle").forEach((m) => {
    const a = agents.find((x) => x.a.name === m.name);
    const x = X(D.time.driven_m[m.idx]);
    svgEl("line", { x1: x, x2: x, y1: 4, y2: H - 16, stroke: a ? a.a.color : "#000", class: "tl-mark" }, svg);
  });
  const cursor = svgEl("line", { x1: P, x2: P, y1: 0, y2: H - 14, class: "tl-cursor" }, svg);
  svg.addEventListener("click", (ev) => {
    const r = svg.getBoundingClientRect();
    const metres = (((ev.clientX - r.left) / r.width) * W - P) / (W - P - 8) * dmax;
    setRow(Math.max(0, last(D.time.driven_m, metres)));
  });

  /* ---- one moment ---- */
  let current = -1;
  function setRow(i) {
    i = Math.max(0, Math.min(N - 1, Math.round(i)));
    current = i;
    slider.value = i;
    const t = D.time;
    clock.textContent = `frame ${t.frame[i]}` + (t.t_s ? ` · ${t.t_s[i].toFixed(1)} s` : "") + ` · ${t.driven_m[i].toFixed(0)} m`;
    status.textContent = `Frame ${t.frame[i]}, ${t.driven_m[i].toFixed(0)} m driven`;
    if (truthMarker) { truthMarker.setLatLng(D.truth[i]); truthTrail.setLatLngs(D.truth.slice(0, i + 1)); }
    agents.forEach((s) => {
      const k = last(s.a.idx, i);
      s.shown = null;
      if (k < 0) { s.g.removeLayer(s.marker); s.road.setLatLngs([]); s.trail.setLatLngs([]); s.value.textContent = "no answer yet"; return; }
      const line = s.a.unit === "road" ? roadLines[s.a.edge[k]] || [] : [];
      s.road.setLatLngs(line);
      let pos = s.a.pos ? s.a.pos[k] : null;
      if (!pos && line.length) pos = line[Math.floor(line.length / 2)];
      if (pos) { s.marker.setLatLng(pos); s.g.addLayer(s.marker); s.shown = pos; } else s.g.removeLayer(s.marker);
      s.trail.setLatLngs(s.count.length ? s.pts.slice(0, s.count[k]) : []);
      s.value.textContent = `${s.a.unit} ${s.a.edge[k]} · ${pct(s.a.conf[k])}${s.a.conf[k] >= D.sure ? " ✓" : ""}`;
    });
    if (D.belief) {
      const b = last(D.belief.idx, i);
      beliefRoads.clearLayers();
      beliefBox.textContent = "";
      heat.setLatLngs(b >= 0 ? D.belief.heat[b] : []);
      (b >= 0 ? D.belief.roads[b] : []).forEach(([e, p]) => {
        if (roadLines[e]) L.polyline(roadLines[e], { color: heatColor(p), weight: 3 + 9 * p, opacity: 0.9 })
          .bindTooltip(`${D.belief.names[e]} (road ${e}): ${pct(p)}`).addTo(beliefRoads);
        el("li", { text: `${pct(p)}  ${D.belief.names[e]} (road ${e})` }, beliefBox);
      });
      beliefRoads.eachLayer((l) => l.bringToFront());
      window.topolocViewer && (window.topolocViewer._belief = b);
    }
    if (img) { const k = last(D.images.idx, i); if (k >= 0) img.src = D.images.src[k]; }
    if (textBox) { const k = last(D.text.idx, i); textBox.textContent = k >= 0 ? D.text.text[k] : ""; }
    if (drive && drive.d) {
      const d = drive.d, k = last(d.idx, i);
      drive.shown = null;
      if (k < 0) {
        drive.g.removeLayer(drive.vehicle); drive.trail.setLatLngs([]);
        driveBox.textContent = `${d.label}: not started (its route starts further along)`;
      } else {
        drive.vehicle.setLatLng(d.pos[k]).setTooltipContent(d.text[k].split(" · ")[2]);
        drive.g.addLayer(drive.vehicle);
        drive.trail.setLatLngs(d.pos.slice(0, k + 1));
        drive.shown = d.pos[k];
        driveBox.textContent = `${d.label} — ${d.text[k]}` + (k === d.pos.length - 1 ? " (stopped)" : "");
      }
    }
    const x = X(t.driven_m[i]);
    cursor.setAttribute("x1", x); cursor.setAttribute("x2", x);
  }
  slider.addEventListener("input", () => setRow(+slider.value));
  let timer = null;
  play.addEventListener("click", () => {
    if (timer) { clearInterval(timer); timer = null; play.textContent = "▶"; return; }
    play.textContent = "❚❚";
    timer = setInterval(() => {
      const next = current + Math.max(1, Math.round(N / 900)) * +speed.value;
      setRow(next >= N - 1 ? N - 1 : next);
      if (next >= N - 1) play.click();
    }, 40);
  });
  window.topolocViewer = {
    map, data: D, setRow, row: () => current,
    agentLatLng: (name) => { const s = agents.find((x) => x.a.name === name); return s && s.shown && map.hasLayer(s.g) ? s.shown : null; },
    visible: (name) => { const s = agents.find((x) => x.a.name === name); return !!s && map.hasLayer(s.g); },
    truthLatLng: () => (truthMarker ? [truthMarker.getLatLng().lat, truthMarker.getLatLng().lng] : null),
    beliefKey: () => (D.belief ? JSON.stringify(D.belief.roads[last(D.belief.idx, current)] || []) : ""),
    heatPoints: () => (heat ? heat._latlngs.length : 0),
    selectDrive: (k) => selectDrive(k),
    driveKey: () => (drive && drive.d ? drive.d.key : null),
    driveLatLng: () => (drive && drive.shown && map.hasLayer(drive.g) && drive.g.hasLayer(drive.vehicle)
      ? [drive.vehicle.getLatLng().lat, drive.vehicle.getLatLng().lng] : null),
    driveText: () => (driveBox ? driveBox.textContent : null),
  };
  if (drive) selectDrive(0);
  setRow(0);
  document.body.setAttribute("data-topoloc-ready", "1");
})();
