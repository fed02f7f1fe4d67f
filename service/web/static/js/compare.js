// What the 3-D viewer shows: the input right after it is read, then input and result with the
// per-point deviation, both within the display budget (decimated for display only).

import { apiFetch } from "./api.js";
import {
  decodePreview, deviations, displayPlan, resultPositions, setDisplayBudget, take, takeMax,
} from "./geometry.js";
import { CompareViewer, drawColorbar } from "./viewer.js";
import { $, fmt } from "./ui.js";

let viewer = null;

function getViewer() {
  if (!viewer) {
    viewer = new CompareViewer($("#pane-before"), $("#pane-after"));
    setDisplayBudget(viewer.software ? "software" : "gpu");
    drawColorbar($("#legend-bar"));
  }
  return viewer;
}

function decimationNote(geom, plan) {
  if (!plan.decimated) return "";
  const faces = geom.faces ? `, ${fmt(plan.faces.length / 3)} of ${fmt(geom.faces.length / 3)} faces` : "";
  const why = viewer?.software ? " (software WebGL: smaller display budget)" : "";
  return `Decimated for display only${why}: showing ${fmt(plan.keep.length)} of ${fmt(geom.n)} points${faces}; `
    + "the smoothing uses every point.";
}

/** Show a freshly read input (POST /v1/info?preview=true answer) in the left pane. */
export function showInputView(info) {
  const v = getViewer(); // first: it chooses the display budget
  const geom = decodePreview(info.preview);
  const plan = displayPlan(geom);
  v.show({ kind: info.kind, dimension: geom.dimension, before: take(geom.positions, plan.keep), after: null,
    faces: plan.faces, segments: plan.segments, deviation: null, vmax: 0 });
  $("#legend").hidden = true;
  $("#pane-after").dataset.resultLoaded = "false";
  $("#viewer-note").textContent = decimationNote(geom, plan);
  return { geom, plan, viewer: v };
}

function showLegend(scale, vmax) {
  const legend = $("#legend");
  legend.hidden = false;
  legend.dataset.unchanged = "false";
  $("#legend-unchanged").hidden = true;
  $("#legend-min").textContent = "0";
  $("#legend-mid").textContent = fmt(scale / 2, 3);
  $("#legend-max").textContent = scale < vmax ? `≥ ${fmt(scale, 3)}` : fmt(scale, 3);
}

/** The legend of a result that is the input: "unchanged" and why, no colour bar. */
function showUnchanged(why) {
  const legend = $("#legend");
  legend.hidden = false;
  legend.dataset.unchanged = "true";
  const text = $("#legend-unchanged");
  text.hidden = false;
  text.textContent = `unchanged — ${why}`;
}

/** Unit roundoff of float32, the display copy's precision. */
const FLOAT32_ROUNDING = 2 ** -24;

/**
 * Why the result counts as unchanged, or null: the report says so (nothing smoothed), or the
 * largest deviation is below float32 rounding of the coordinates' scale (a colour map of it
 * would paint rounding as "everything moved").
 */
export function unchangedReason(report, vmax, positions) {
  if (report?.unchanged === "copied") return "returned unchanged: the result file is the input's bytes";
  if (report?.unchanged === "converted") return "converted unchanged: the input's points, in another format";
  if (report && report.max_displacement === 0) return "no point moved";
  let scale = 0;
  for (let i = 0; i < positions.length; i++) {
    const a = Math.abs(positions[i]);
    if (a > scale) scale = a;
  }
  if (vmax <= 8 * FLOAT32_ROUNDING * scale) {
    return `largest deviation ${fmt(vmax, 2)} is float32 rounding of coordinates of size ${fmt(scale, 3)}`;
  }
  return null;
}

/** The colour scale's top: the 99th percentile, so that a few outliers do not darken the rest. */
function colourScale(dev, vmax) {
  if (dev.length < 100) return vmax;
  const sorted = Float32Array.from(dev).sort();
  const p99 = sorted[Math.floor(0.99 * (sorted.length - 1))];
  return p99 > 0 ? p99 : vmax;
}

/** Line segments of a JSON geometry: its edges and its polylines' consecutive pairs. */
function jsonSegments(json) {
  const out = (json.edges || []).flat();
  for (const p of json.polylines || []) {
    const ix = p.indices || [];
    for (let k = 1; k < ix.length; k++) out.push(ix[k - 1], ix[k]);
    if (p.closed && ix.length > 2) out.push(ix[ix.length - 1], ix[0]);
  }
  return out.length ? Uint32Array.from(out) : null;
}

/**
 * Fetch the result of a succeeded `job` as JSON and show it next to `input` (the input object
 * of the page when the job was submitted from it; null for a job opened from the list).
 */
export async function loadResultView(job, input) {
  const response = await apiFetch(`${job.links.result}?output_format=json`);
  const json = await response.json();
  const v = getViewer();
  if (!input || input.geom.n !== json.points.length) {
    // Only the result is known here: show it alone.
    const n = json.points.length;
    const first = json.points[0] || [0, 0, 0];
    const geom = { n, dimension: first.length, origin: [first[0] || 0, first[1] || 0, first[2] || 0],
      faces: json.faces ? Uint32Array.from(json.faces.flat()) : null, segments: jsonSegments(json) };
    geom.positions = resultPositions(json, geom.origin);
    const plan = displayPlan(geom);
    const after = take(geom.positions, plan.keep);
    v.show({ kind: job.report?.kind, dimension: geom.dimension, before: after, after,
      faces: plan.faces, segments: plan.segments, deviation: null, vmax: 0 });
    $("#viewer-note").textContent = "The input of this job is not loaded in this page: both panes show the result.";
    $("#legend").hidden = true;
    const same = unchangedReason(job.report, Infinity, []);
    if (same) showUnchanged(same);
    $("#pane-after").dataset.unchanged = String(Boolean(same));
  } else {
    const { geom, plan } = input;
    const after = resultPositions(json, geom.origin);
    const dev = deviations(geom.positions, after);
    const vmax = dev.reduce((m, x) => (x > m ? x : m), 0);
    const scale = colourScale(dev, vmax);
    const same = unchangedReason(job.report, vmax, geom.positions);
    v.show({ kind: input.info.kind, dimension: geom.dimension, before: take(geom.positions, plan.keep),
      after: take(after, plan.keep), faces: plan.faces, segments: plan.segments,
      deviation: same ? null : takeMax(dev, plan.of, plan.keep.length), vmax: same ? 0 : scale },
    { refit: false });
    if (same) showUnchanged(same); else showLegend(scale, vmax);
    $("#pane-after").dataset.unchanged = String(Boolean(same));
    const rms = Math.sqrt(dev.reduce((s, x) => s + x * x, 0) / Math.max(1, dev.length));
    const note = $("#viewer-note");
    const measured = same
      ? `Nothing was smoothed; the page's own deviations (RMS ${fmt(rms)}, max ${fmt(vmax)}) are float32 rounding of its display copy.`
      : `Deviation per point: RMS ${fmt(rms)}, max ${fmt(vmax)} (data units).`;
    note.textContent = `${decimationNote(geom, plan)} ${measured}`.trim();
    note.dataset.vmax = String(vmax);
    note.dataset.rms = String(rms);
  }
  $("#pane-after").dataset.resultLoaded = "true";
}
