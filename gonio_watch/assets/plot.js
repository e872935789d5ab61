/* A small SVG plotter for the live view: a linear x axis, a log10 y axis, points (filled or
   hollow, with optional error bars and rings) and lines. Each call redraws the whole figure
   from its spec; every point is an element of class "pt" (tests count them). */
"use strict";

const GonioPlot = (() => {
  const NS = "http://www.w3.org/2000/svg";
  const MARGIN = { left: 56, right: 10, top: 22, bottom: 34 };

  function esc(text) {
    return String(text).replace(/[&<>"]/g, (c) => ({ "&": "&amp;", "<": "&lt;", ">": "&gt;", '"': "&quot;" })[c]);
  }

  /* Linear ticks at 1, 2 or 5 times a power of ten, about `count` of them. */
  function linearTicks(lo, hi, count) {
    const raw = (hi - lo) / Math.max(count, 1);
    const power = Math.pow(10, Math.floor(Math.log10(raw)));
    const step = [1, 2, 5, 10].map((m) => m * power).find((s) => s >= raw) || raw;
    const out = [];
    for (let v = Math.ceil(lo / step) * step; v <= hi + 1e-9 * step; v += step) out.push(+v.toFixed(10));
    return out;
  }

  /* Log ticks: the decades in [lo, hi] (log10 units); 2 and 5 times them for a narrow range. */
  function logTicks(lo, hi) {
    const out = [];
    for (let d = Math.floor(lo); d <= Math.ceil(hi); d++) {
      for (const m of hi - lo < 2 ? [1, 2, 5] : [1]) {
        const v = d + Math.log10(m);
        if (v >= lo - 1e-9 && v <= hi + 1e-9) out.push({ v, major: m === 1, d, m });
      }
    }
    return out;
  }

  function tickLabel(t) {
    return `${t.m}e${t.d}`;
  }

  /* The y range (log10 units) that holds the positive values, whole decades, at least one. */
  function logRange(values, fallback) {
    const pos = values.filter((v) => v > 0 && isFinite(v));
    if (!pos.length) return fallback;
    let lo = Math.floor(Math.log10(Math.min(...pos)) - 0.1);
    let hi = Math.ceil(Math.log10(Math.max(...pos)) + 0.1);
    if (hi - lo < 1) { lo -= 0.5; hi += 0.5; }
    return [lo, hi];
  }

  /* Draw spec into svg: {x: [lo, hi], y: [lo, hi] (log10), xticks, xlabel, ylabel, title,
     points: [{x, y, color, hollow, ring, err: [lo, hi], tip}], lines: [{x: [], y: [], color,
     dash}]}. A point whose y is not positive or not finite sits on the bottom edge as a
     triangle (no reading, or nothing above the dark level). */
  function draw(svg, spec) {
    const box = svg.getBoundingClientRect();
    const width = Math.max(box.width, 200), height = Math.max(box.height, 150);
    const pw = width - MARGIN.left - MARGIN.right, ph = height - MARGIN.top - MARGIN.bottom;
    const [x0, x1] = spec.x, [l0, l1] = spec.y;
    const sx = (x) => MARGIN.left + ((x - x0) / (x1 - x0)) * pw;
    const sy = (y) => MARGIN.top + ph - ((Math.log10(y) - l0) / (l1 - l0)) * ph;
    const inside = (y) => y > 0 && isFinite(y);
    const clipId = "clip-" + svg.id;
    const parts = [`<defs><clipPath id="${clipId}"><rect x="${MARGIN.left}" y="${MARGIN.top}" width="${pw}" height="${ph}"/></clipPath></defs>`];
    for (const t of spec.xticks || linearTicks(x0, x1, Math.max(3, Math.round(pw / 70)))) {
      const X = sx(t).toFixed(1);
      parts.push(`<line class="grid" x1="${X}" x2="${X}" y1="${MARGIN.top}" y2="${MARGIN.top + ph}"/>`,
        `<text class="tick" x="${X}" y="${MARGIN.top + ph + 13}" text-anchor="middle">${t}</text>`);
    }
    for (const t of logTicks(l0, l1)) {
      const Y = (MARGIN.top + ph - ((t.v - l0) / (l1 - l0)) * ph).toFixed(1);
      parts.push(`<line class="grid" x1="${MARGIN.left}" x2="${MARGIN.left + pw}" y1="${Y}" y2="${Y}"/>`);
      if (t.major || l1 - l0 < 2) parts.push(`<text class="tick" x="${MARGIN.left - 4}" y="${+Y + 4}" text-anchor="end">${tickLabel(t)}</text>`);
    }
    parts.push(`<rect class="frame" x="${MARGIN.left}" y="${MARGIN.top}" width="${pw}" height="${ph}"/>`);
    if (spec.title) parts.push(`<text class="title" x="${MARGIN.left}" y="${MARGIN.top - 7}">${esc(spec.title)}</text>`);
    parts.push(`<text class="axis-label" x="${MARGIN.left + pw / 2}" y="${height - 4}" text-anchor="middle">${esc(spec.xlabel || "")}</text>`,
      `<text class="axis-label" transform="translate(12 ${MARGIN.top + ph / 2}) rotate(-90)" text-anchor="middle">${esc(spec.ylabel || "")}</text>`);
    parts.push(`<g clip-path="url(#${clipId})">`);
    for (const line of spec.lines || []) {
      let d = "", pen = "M";
      line.x.forEach((x, k) => {
        const y = line.y[k];
        if (y === null || !inside(y)) { pen = "M"; return; }
        d += `${pen}${sx(x).toFixed(1)},${sy(y).toFixed(1)}`;
        pen = "L";
      });
      if (d) parts.push(`<path d="${d}" fill="none" stroke="${line.color}" stroke-width="1.4"${line.dash ? ` stroke-dasharray="${line.dash}"` : ""}/>`);
    }
    for (const p of spec.points) {
      if (!p.err || !inside(p.y)) continue;
      const lo = Math.max(p.err[0], Math.pow(10, l0 - 1)), hi = p.err[1];
      if (inside(hi)) parts.push(`<line class="err" x1="${sx(p.x).toFixed(1)}" x2="${sx(p.x).toFixed(1)}" y1="${sy(lo).toFixed(1)}" y2="${sy(hi).toFixed(1)}"/>`);
    }
    parts.push("</g>");
    for (const p of spec.points) {
      const X = sx(p.x).toFixed(1), tip = p.tip ? `<title>${esc(p.tip)}</title>` : "";
      const fill = p.hollow ? "#fff" : p.color;
      if (!inside(p.y)) {
        const Y = MARGIN.top + ph;
        parts.push(`<path class="pt below" d="M${X},${Y - 2}l-4,-7h8z" fill="${fill}" stroke="${p.color}">${tip}</path>`);
        continue;
      }
      const Y = Math.min(Math.max(sy(p.y), MARGIN.top), MARGIN.top + ph).toFixed(1);
      if (p.ring) parts.push(`<circle class="ring" cx="${X}" cy="${Y}" r="6" fill="none" stroke="${p.ring}" stroke-width="1.5"/>`);
      parts.push(`<circle class="pt${p.hollow ? " flagged" : ""}" cx="${X}" cy="${Y}" r="3" fill="${fill}" stroke="${p.color}">${tip}</circle>`);
    }
    svg.setAttribute("viewBox", `0 0 ${width} ${height}`);
    svg.innerHTML = parts.join("");
  }

  /* A legend entry's swatch: a point (filled, hollow, ringed) or a line. */
  function swatch(kind, color, extra) {
    const body = {
      point: `<circle cx="8" cy="6" r="3.5" fill="${color}" stroke="${color}"/>`,
      hollow: `<circle cx="8" cy="6" r="3.5" fill="#fff" stroke="${color}"/>`,
      ring: `<circle cx="8" cy="6" r="3" fill="#555" stroke="#555"/><circle cx="8" cy="6" r="5.5" fill="none" stroke="${color}" stroke-width="1.5"/>`,
      below: `<path d="M8,10l-4,-7h8z" fill="#fff" stroke="${color}"/>`,
      line: `<line x1="0" x2="16" y1="6" y2="6" stroke="${color}" stroke-width="1.6"${extra ? ` stroke-dasharray="${extra}"` : ""}/>`,
    }[kind];
    return `<svg width="16" height="12" xmlns="${NS}">${body}</svg>`;
  }

  function legend(el, entries) {
    el.innerHTML = entries.map((e) => `<span>${swatch(e.kind, e.color, e.dash)}${esc(e.label)}</span>`).join("");
  }

  return { draw, legend, logRange, linearTicks };
})();
