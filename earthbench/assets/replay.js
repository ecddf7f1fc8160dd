(function () {
  var dataEl = document.getElementById('rp-data');
  if (!dataEl) return;
  var replays = JSON.parse(dataEl.textContent);
  var sel = document.getElementById('rp-run'), canvas = document.getElementById('rp-canvas');
  var slider = document.getElementById('rp-time'), clock = document.getElementById('rp-clock');
  var playBtn = document.getElementById('rp-play'), logEl = document.getElementById('rp-log');
  var nowEl = document.getElementById('rp-now'), verdictEl = document.getElementById('rp-verdict');
  var ctx = canvas.getContext('2d'), overlays = document.getElementById('rp-overlays');
  var scaleEl = document.getElementById('rp-scale');
  var COLOURS = {excavator: '#e67e00', truck: '#1f66c2', loader: '#2a9d2a'};
  var TERRAIN = [[0, [51, 51, 153]], [0.15, [0, 153, 255]], [0.25, [0, 204, 102]], [0.5, [255, 255, 153]],
                 [0.75, [128, 92, 84]], [1, [255, 255, 255]]];
  var cur = null;  // the loaded replay: {doc, z (Float64Array), applied (events applied), t, image canvas}
  var playing = false, lastFrame = 0;

  function bytes(b64) {
    var s = atob(b64), out = new Uint8Array(s.length);
    for (var i = 0; i < s.length; i++) out[i] = s.charCodeAt(i);
    return out;
  }
  function inflate(packed) {  // "i2:BASE64" or "i4:BASE64" of zlib-compressed little-endian integers
    var stream = new Blob([bytes(packed.slice(3))]).stream().pipeThrough(new DecompressionStream('deflate'));
    return new Response(stream).arrayBuffer().then(function (buf) {
      return packed.slice(0, 2) === 'i2' ? new Int16Array(buf) : new Int32Array(buf);
    });
  }
  function colour(f) {
    f = Math.max(0, Math.min(1, f));
    for (var k = 1; k < TERRAIN.length; k++) {
      if (f <= TERRAIN[k][0]) {
        var a = TERRAIN[k - 1], b = TERRAIN[k], u = (f - a[0]) / (b[0] - a[0]);
        return [0, 1, 2].map(function (c) { return Math.round(a[1][c] + u * (b[1][c] - a[1][c])); });
      }
    }
    return TERRAIN[TERRAIN.length - 1][1];
  }
  function option(doc, n) {
    var o = document.createElement('option');
    o.value = String(n);
    o.textContent = doc.label + ' — ' + doc.verdict;
    return o;
  }
  replays.forEach(function (doc, n) { sel.appendChild(option(doc, n)); });

  function load(n) {
    var doc = replays[n], g = doc.grid;
    sel.value = String(n);
    var deltas = doc.events.map(function (ev) { return ev.delta ? inflate(ev.delta.d) : Promise.resolve(null); });
    return Promise.all([inflate(g.rows)].concat(deltas)).then(function (arr) {
      var rows = arr[0], z = new Int32Array(g.nx * g.ny), first = g.base;
      for (var j = 0; j < g.ny; j++) {
        first += rows[j * g.nx];
        var acc = first;
        z[j * g.nx] = acc;
        for (var i = 1; i < g.nx; i++) { acc += rows[j * g.nx + i]; z[j * g.nx + i] = acc; }
      }
      var img = document.createElement('canvas');
      img.width = g.nx; img.height = g.ny;
      cur = {doc: doc, z: z, deltas: arr.slice(1), applied: 0, t: 0, img: img, imgDirty: true};
      fit();
      slider.value = 0;
      buildLog();
      seek(0);
    });
  }
  function apply(k, sign) {
    var ev = cur.doc.events[k], d = cur.deltas[k], g = cur.doc.grid;
    if (!d) return;
    for (var jj = 0; jj < ev.delta.h; jj++)
      for (var ii = 0; ii < ev.delta.w; ii++)
        cur.z[(ev.delta.j + jj) * g.nx + ev.delta.i + ii] += sign * d[jj * ev.delta.w + ii];
    cur.imgDirty = true;
  }
  function seek(t) {
    var evs = cur.doc.events;
    cur.t = t;
    while (cur.applied < evs.length && evs[cur.applied].t1 <= t + 1e-9) { apply(cur.applied, 1); cur.applied++; }
    while (cur.applied > 0 && evs[cur.applied - 1].t1 > t + 1e-9) { cur.applied--; apply(cur.applied, -1); }
    draw();
  }
  function fit() {
    var g = cur.doc.grid, room = canvas.parentNode.clientWidth - 4 - (scaleEl ? scaleEl.width + 16 : 0);  // the scale beside it
    var w = Math.max(room < 900 ? room : Math.min(room * 0.72, 1100), 240);  // narrow windows: the log goes below
    w = Math.max(Math.min(w, 0.8 * window.innerHeight * g.nx / g.ny), 240);  // a tall map fits the window's height
    canvas.width = Math.round(w);
    canvas.height = Math.round(w * g.ny / g.nx);
    drawScale();
  }
  // the height scale beside the map: the map's colours from its lowest ground (bottom) to its highest (top), in m
  var BAR = {x: 4, w: 16, pad: 8};
  function scaleTicks() {
    var g = cur.doc.grid, h = Math.max(canvas.height, 160), n = 5, out = [];
    for (var k = 0; k < n; k++) {
      var f = k / (n - 1);
      out.push({height: g.lo + f * (g.hi - g.lo), y: Math.round(h - BAR.pad - f * (h - 2 * BAR.pad))});
    }
    return out;
  }
  function drawScale() {
    if (!scaleEl) return;
    var g = cur.doc.grid, h = Math.max(canvas.height, 160), sctx = scaleEl.getContext('2d');
    scaleEl.height = h;
    sctx.clearRect(0, 0, scaleEl.width, h);
    var top = BAR.pad, bottom = h - BAR.pad;
    for (var y = top; y <= bottom; y++) {
      var c = colour((bottom - y) / Math.max(bottom - top, 1));
      sctx.fillStyle = 'rgb(' + c[0] + ',' + c[1] + ',' + c[2] + ')';
      sctx.fillRect(BAR.x, y, BAR.w, 1);
    }
    sctx.strokeStyle = '#000'; sctx.lineWidth = 1;
    sctx.strokeRect(BAR.x + 0.5, top + 0.5, BAR.w - 1, bottom - top);
    sctx.font = '11px sans-serif'; sctx.fillStyle = '#000'; sctx.textBaseline = 'middle';
    var digits = g.hi - g.lo < 0.5 ? 3 : 2;
    scaleTicks().forEach(function (tk) {
      sctx.beginPath(); sctx.moveTo(BAR.x + BAR.w, tk.y + 0.5); sctx.lineTo(BAR.x + BAR.w + 4, tk.y + 0.5); sctx.stroke();
      sctx.fillText(tk.height.toFixed(digits) + ' m', BAR.x + BAR.w + 6, tk.y);
    });
  }
  function toPx(x, y) {
    var g = cur.doc.grid, s = canvas.width / (g.nx * g.r);
    return [(x - g.x0) * s, canvas.height - (y - g.y0) * s];
  }
  function scale() { var g = cur.doc.grid; return canvas.width / (g.nx * g.r); }
  function poly(pts, stroke, fill, dash, width) {
    ctx.beginPath();
    pts.forEach(function (p, k) { var q = toPx(p[0], p[1]); if (k) ctx.lineTo(q[0], q[1]); else ctx.moveTo(q[0], q[1]); });
    ctx.closePath();
    if (fill) { ctx.fillStyle = fill; ctx.fill(); }
    if (stroke) { ctx.setLineDash(dash || []); ctx.lineWidth = width || 1.5; ctx.strokeStyle = stroke; ctx.stroke(); ctx.setLineDash([]); }
  }
  function pose(mid, t) {
    var m = cur.doc.machines[mid], p = m.start.slice();
    for (var s = 0; s < m.segments.length; s++) {
      var seg = m.segments[s];
      if (seg[0][0] > t) break;
      for (var k = 0; k < seg.length; k++) {
        if (seg[k][0] > t) {
          var a = seg[k - 1], b = seg[k], u = (t - a[0]) / Math.max(b[0] - a[0], 1e-9);
          return [a[1] + u * (b[1] - a[1]), a[2] + u * (b[2] - a[2]), a[3] + u * (b[3] - a[3])];
        }
      }
      var last = seg[seg.length - 1];
      p = [last[1], last[2], last[3]];
    }
    return p;
  }
  function badMoves() {
    var out = {};
    cur.doc.events.forEach(function (ev) { if (ev.violations && ev.type === 'move') out[ev.t0 + ':' + ev.machine] = ev; });
    return out;
  }
  function drawPaths(t) {
    var bad = badMoves();
    Object.keys(cur.doc.machines).forEach(function (mid) {
      var m = cur.doc.machines[mid], at = [m.start[0], m.start[1]];
      m.segments.forEach(function (seg) {
        var red = bad[seg[0][0] + ':' + mid];
        var first = toPx(seg[0][1], seg[0][2]), from = toPx(at[0], at[1]);
        if (Math.hypot(first[0] - from[0], first[1] - from[1]) > 0.5 * scale() * 0.05 + 0.5) {
          ctx.beginPath(); ctx.moveTo(from[0], from[1]); ctx.lineTo(first[0], first[1]);
          ctx.setLineDash([4, 4]); ctx.strokeStyle = '#d00'; ctx.lineWidth = 2; ctx.stroke(); ctx.setLineDash([]);
        }
        ctx.beginPath();
        seg.forEach(function (smp, k) { var q = toPx(smp[1], smp[2]); if (k) ctx.lineTo(q[0], q[1]); else ctx.moveTo(q[0], q[1]); });
        ctx.strokeStyle = red ? '#d00' : COLOURS[mid] || '#000';
        ctx.globalAlpha = seg[0][0] <= t ? 0.95 : 0.3;
        ctx.lineWidth = red ? 2.5 : 1.5;
        ctx.stroke();
        ctx.globalAlpha = 1;
        var last = seg[seg.length - 1];
        at = [last[1], last[2]];
      });
    });
  }
  function drawMachine(mid, p, red) {
    var q = toPx(p[0], p[1]), s = scale();
    var inside = q[0] >= 0 && q[0] <= canvas.width && q[1] >= 0 && q[1] <= canvas.height;
    if (!inside) {  // off the map: a marker at the edge, pointing to where the machine is
      var cx = Math.max(10, Math.min(canvas.width - 10, q[0])), cy = Math.max(10, Math.min(canvas.height - 10, q[1]));
      var ang = Math.atan2(q[1] - cy, q[0] - cx);
      ctx.beginPath();
      ctx.moveTo(cx + 9 * Math.cos(ang), cy + 9 * Math.sin(ang));
      ctx.lineTo(cx + 7 * Math.cos(ang + 2.4), cy + 7 * Math.sin(ang + 2.4));
      ctx.lineTo(cx + 7 * Math.cos(ang - 2.4), cy + 7 * Math.sin(ang - 2.4));
      ctx.closePath();
      ctx.fillStyle = COLOURS[mid] || '#000'; ctx.fill();
      ctx.lineWidth = red ? 3 : 1; ctx.strokeStyle = red ? '#d00' : '#000'; ctx.stroke();
      ctx.font = '12px sans-serif'; ctx.fillStyle = '#000';
      ctx.textAlign = cx > canvas.width / 2 ? 'right' : 'left';
      ctx.fillText(mid + ' (' + p[0].toFixed(1) + ', ' + p[1].toFixed(1) + ')',
                   cx + (cx > canvas.width / 2 ? -12 : 12), cy + (cy > canvas.height / 2 ? -10 : 16));
      ctx.textAlign = 'left';
      return;
    }
    ctx.beginPath(); ctx.arc(q[0], q[1], Math.max(4, 0.35 * s), 0, 2 * Math.PI);
    ctx.fillStyle = COLOURS[mid] || '#000'; ctx.fill();
    ctx.lineWidth = red ? 3 : 1.5; ctx.strokeStyle = red ? '#d00' : '#000'; ctx.stroke();
    ctx.beginPath(); ctx.moveTo(q[0], q[1]);
    ctx.lineTo(q[0] + Math.cos(p[2]) * Math.max(10, 0.8 * s), q[1] - Math.sin(p[2]) * Math.max(10, 0.8 * s));
    ctx.strokeStyle = '#000'; ctx.lineWidth = 2; ctx.stroke();
  }
  function terrainImage() {
    var g = cur.doc.grid, ictx = cur.img.getContext('2d'), im = ictx.createImageData(g.nx, g.ny);
    var span = Math.max(g.hi - g.lo, 1e-6);
    for (var j = 0; j < g.ny; j++) {
      for (var i = 0; i < g.nx; i++) {
        var c = colour(cur.z[j * g.nx + i] * g.q / span), o = ((g.ny - 1 - j) * g.nx + i) * 4;
        im.data[o] = c[0]; im.data[o + 1] = c[1]; im.data[o + 2] = c[2]; im.data[o + 3] = 255;
      }
    }
    ictx.putImageData(im, 0, 0);
    cur.imgDirty = false;
  }
  function draw() {
    var doc = cur.doc, t = cur.t;
    if (cur.imgDirty) terrainImage();
    ctx.imageSmoothingEnabled = false;
    ctx.drawImage(cur.img, 0, 0, canvas.width, canvas.height);
    var loaded = cur.applied ? doc.events[cur.applied - 1].loaded : 0;
    clock.textContent = 't = ' + t.toFixed(1) + ' / ' + doc.makespan.toFixed(1) + ' s · loaded ' + loaded.toFixed(2) +
      ' of ' + doc.target.toFixed(2) + ' m³';
    if (!overlays.checked) return;
    poly(doc.dig_area, '#000', null, [6, 4], 1.2);
    doc.keep_outs.forEach(function (k) { poly(k, '#d00', 'rgba(220,0,0,0.25)'); });
    drawPaths(t);
    var active = {}, now = [];
    doc.events.forEach(function (ev, k) {
      if (ev.t0 > t + 1e-9) return;
      var done = ev.t1 <= t + 1e-9, bad = !!ev.violations;
      if (!done) { active[ev.machine] = ev; now.push(ev); }
      if (ev.fp) poly(ev.fp, bad ? '#d00' : (done ? '#000' : '#fff'), bad ? 'rgba(220,0,0,0.3)' : null, null, bad ? 2.5 : 1.2);
      if (ev.type === 'dump') {
        var tr = doc.machines.truck ? pose('truck', ev.t0) : pose(ev.machine, ev.t0), q = toPx(tr[0], tr[1]);
        ctx.fillStyle = bad ? '#d00' : '#5b3a1a'; ctx.strokeStyle = '#fff'; ctx.lineWidth = 1;
        ctx.fillRect(q[0] + 8 + 9 * (k % 5), q[1] - 18, 8, 8); ctx.strokeRect(q[0] + 8 + 9 * (k % 5), q[1] - 18, 8, 8);
      }
      if (bad && ev.type !== 'move' && !ev.fp) {
        var p = pose(ev.machine, ev.t0), r = toPx(p[0], p[1]);
        ctx.beginPath(); ctx.arc(r[0], r[1], 14, 0, 2 * Math.PI); ctx.strokeStyle = '#d00'; ctx.lineWidth = 3; ctx.stroke();
      }
    });
    if (doc.reach && doc.machines.excavator) {
      var e = pose('excavator', t), c = toPx(e[0], e[1]), s = scale();
      ctx.setLineDash([3, 5]); ctx.strokeStyle = 'rgba(0,0,0,0.55)'; ctx.lineWidth = 1;
      doc.reach.forEach(function (r) { ctx.beginPath(); ctx.arc(c[0], c[1], r * s, 0, 2 * Math.PI); ctx.stroke(); });
      ctx.setLineDash([]);
    }
    Object.keys(doc.machines).forEach(function (mid) {
      var ev = active[mid];
      drawMachine(mid, pose(mid, t), !!(ev && ev.violations));
    });
    nowEl.textContent = now.length
      ? 'now: ' + now.map(function (ev) { return ev.machine + ' ' + ev.type + ' (action ' + ev.a + ')'; }).join(', ')
      : '';
    Array.prototype.forEach.call(logEl.children, function (li) {
      li.classList.toggle('rp-done', parseFloat(li.getAttribute('data-t')) <= t + 1e-9);
    });
  }
  function buildLog() {
    var doc = cur.doc;
    verdictEl.textContent = doc.label + ': ' + doc.verdict;
    verdictEl.className = doc.verdict === 'valid' ? '' : 'rp-bad';
    while (logEl.firstChild) logEl.removeChild(logEl.firstChild);
    doc.plan_violations.forEach(function (v) {
      var li = document.createElement('li');
      li.className = 'rp-bad'; li.setAttribute('data-t', '0');
      li.textContent = 'plan: ' + v.rule + ' — ' + v.message;
      logEl.appendChild(li);
    });
    doc.events.forEach(function (ev) {
      if (ev.type === 'move' && !ev.violations) return;
      var li = document.createElement('li');
      li.setAttribute('data-t', String(ev.t0));
      li.textContent = ev.t0.toFixed(1) + ' s: ' + ev.machine + ' ' + ev.type + ' (action ' + ev.a + ')' +
        (ev.violations ? ' — ' + ev.violations.map(function (v) { return v.rule + ': ' + v.message; }).join('; ') : '');
      if (ev.violations) li.className = 'rp-bad';
      li.addEventListener('click', function () { setTime(ev.t1); });
      logEl.appendChild(li);
    });
  }
  function setTime(t) {
    if (!cur) return;
    t = Math.max(0, Math.min(cur.doc.makespan, t));
    slider.value = String(Math.round(1000 * t / Math.max(cur.doc.makespan, 1e-9)));
    seek(t);
  }
  function step(dir) {
    if (!cur) return;
    var ts = cur.doc.events.map(function (ev) { return ev.t1; }), t = cur.t;
    var next = dir > 0 ? ts.filter(function (x) { return x > t + 1e-6; })[0]
                       : ts.filter(function (x) { return x < t - 1e-6; }).pop();
    setTime(next === undefined ? (dir > 0 ? cur.doc.makespan : 0) : next);
  }
  function tick(ts) {
    if (!playing || !cur) return;
    var dt = lastFrame ? (ts - lastFrame) / 1000 : 0;
    lastFrame = ts;
    var t = cur.t + dt * Math.max(cur.doc.makespan / 20, 1);  // a whole plan plays in about 20 s
    if (t >= cur.doc.makespan) { setTime(cur.doc.makespan); togglePlay(false); return; }
    setTime(t);
    requestAnimationFrame(tick);
  }
  function togglePlay(on) {
    playing = on === undefined ? !playing : on;
    playBtn.textContent = playing ? '❚❚ Pause' : '▶ Play';
    if (playing) {
      if (cur.t >= cur.doc.makespan) setTime(0);
      lastFrame = 0; requestAnimationFrame(tick);
    }
  }
  slider.addEventListener('input', function () {
    if (cur) seek(cur.doc.makespan * parseFloat(slider.value) / 1000);
  });
  sel.addEventListener('change', function () { togglePlay(false); load(parseInt(sel.value, 10)); });
  overlays.addEventListener('change', function () { if (cur) draw(); });
  playBtn.addEventListener('click', function () { if (cur) togglePlay(); });
  document.getElementById('rp-prev').addEventListener('click', function () { step(-1); });
  document.getElementById('rp-next').addEventListener('click', function () { step(1); });
  window.addEventListener('resize', function () { if (cur) { fit(); draw(); } });
  // a ▶ button next to every run of the runs tables that has a replay
  var byRun = {};
  replays.forEach(function (doc, n) { if (doc.run !== null) byRun[String(doc.run)] = n; });
  document.querySelectorAll('table.runs tbody tr').forEach(function (tr) {
    var n = byRun[tr.cells[0].textContent.trim()];
    if (n === undefined) return;
    var b = document.createElement('button');
    b.type = 'button'; b.className = 'rp-open'; b.textContent = '▶'; b.title = 'replay this run';
    b.addEventListener('click', function (ev) {
      ev.stopPropagation();
      sel.value = String(n); togglePlay(false);
      load(n).then(function () { document.getElementById('replay').scrollIntoView(); });
    });
    tr.cells[0].appendChild(b);
  });
  // the links under each ranking table ("Replay a run"): open that run in the viewer
  document.querySelectorAll('a.rp-link').forEach(function (a) {
    var n = byRun[a.getAttribute('data-run')];
    if (n === undefined) { a.removeAttribute('href'); return; }
    a.addEventListener('click', function () { sel.value = String(n); togglePlay(false); load(n); });
  });
  window.earthbenchReplay = {load: load, setTime: setTime, state: function () {
    return cur ? {run: cur.doc.run, t: cur.t, applied: cur.applied, makespan: cur.doc.makespan} : null; },
    scale: function () { return cur ? {lo: cur.doc.grid.lo, hi: cur.doc.grid.hi, ticks: scaleTicks(), bar: BAR} : null; }};
  window.earthbenchReplayReady = load(0);
})();
