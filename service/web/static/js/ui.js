// Small DOM helpers: number formatting, key-value tables, and problem details shown next to
// the field at fault.

export const $ = (sel, root = document) => root.querySelector(sel);
export const $$ = (sel, root = document) => [...root.querySelectorAll(sel)];

export function fmt(v, digits = 4) {
  if (v === null || v === undefined) return "–";
  if (typeof v !== "number") return String(v);
  if (!Number.isFinite(v)) return String(v);
  if (Number.isInteger(v) && Math.abs(v) < 1e9) return v.toLocaleString("en-US");
  const a = Math.abs(v);
  return a !== 0 && (a < 1e-3 || a >= 1e5) ? v.toExponential(digits - 1) : String(Number(v.toPrecision(digits)));
}

/**
 * A bounding box readable at any magnitude (issue 41): when an axis lies far from 0 against
 * its extent (UTM eastings, 5e5 m for a 110 m scan), a round offset is shown once and the
 * ranges about it: "offset (500,000, 5,000,000, 0); [0.01, 110] × [0, 110] × [9.2, 10.8]".
 */
export function bboxText(box) {
  const lo = box.min || [], hi = box.max || [];
  const offsets = lo.map((l, d) => {
    const ext = Math.abs(hi[d] - l);
    if (!Number.isFinite(l) || Math.abs(l) < 1000 * Math.max(ext, 1e-9)) return 0;
    const step = 10 ** Math.ceil(Math.log10(Math.max(ext, 1e-9)) + 1); // a round value below lo
    return Math.floor(l / step) * step;
  });
  const ranges = lo.map((l, d) => `[${fmt(l - offsets[d])}, ${fmt(hi[d] - offsets[d])}]`).join(" × ");
  return offsets.some((o) => o !== 0) ? `offset (${offsets.map((o) => fmt(o)).join(", ")}); ${ranges}` : ranges;
}

export function seconds(s) {
  if (s === null || s === undefined || !Number.isFinite(s)) return "–";
  return s < 1 ? `${(s * 1000).toFixed(0)} ms` : s < 120 ? `${s.toFixed(2)} s` : `${Math.floor(s / 60)} min ${Math.round(s % 60)} s`;
}

/** Fill a <table> with rows [label, value(s)...]; values may be nodes or text. */
export function fillTable(table, rows) {
  table.replaceChildren();
  for (const row of rows) {
    const tr = document.createElement("tr");
    row.forEach((cell, i) => {
      const td = document.createElement(i % 2 === 0 ? "th" : "td");
      if (cell instanceof Node) td.append(cell); else td.textContent = cell;
      tr.append(td);
    });
    table.append(tr);
  }
}

export function clearErrors(root = document) {
  for (const node of $$("[data-error-for]", root)) node.textContent = "";
  for (const node of $$(".has-error", root)) node.classList.remove("has-error");
}

/** The error slot for a problem's field: exact, then the nearest enclosing field, then `fallback`. */
function slotFor(field, fallback) {
  const aliases = { geometry: "file", "geometry.points": "file", "content-type": "file", name: "file" };
  let name = field || "";
  while (name) {
    const node = document.querySelector(`[data-error-for="${CSS.escape(aliases[name] || name)}"]`);
    if (node) return { node, field: aliases[name] || name };
    name = name.includes(".") ? name.slice(0, name.lastIndexOf(".")) : "";
  }
  return { node: document.querySelector(`[data-error-for="${fallback}"]`), field: fallback };
}

/**
 * Show a ProblemError (or any Error) next to the fields it names.
 * @param {Error} err
 * @param {string} fallback slot used when no field matches (e.g. "params", "file")
 */
export function showProblem(err, fallback = "body") {
  const entries = typeof err.fieldErrors === "function" ? err.fieldErrors() : [{ field: "", message: err.message }];
  const title = err.problem?.title;
  for (const { field, message } of entries) {
    const { node, field: at } = slotFor(field, fallback);
    if (!node) continue;
    const text = title && !message.startsWith(title) ? `${title}: ${message}` : message;
    node.textContent = node.textContent ? `${node.textContent}\n${text}` : text;
    document.querySelector(`[data-field="${CSS.escape(at)}"]`)?.classList.add("has-error");
    if (err.problem?.valid_range && /tau|rms/.test(at)) {
      node.textContent += ` (valid range: ${err.problem.valid_range.map((v) => fmt(v)).join(" – ")})`;
    }
  }
}

/** Save a Blob under `name` (an <a download> click). */
export function saveBlob(blob, name) {
  const url = URL.createObjectURL(blob);
  const a = document.createElement("a");
  a.href = url;
  a.download = name;
  document.body.append(a);
  a.click();
  a.remove();
  setTimeout(() => URL.revokeObjectURL(url), 60000);
}

export function filenameFrom(response, fallback) {
  const cd = response.headers.get("Content-Disposition") || "";
  const m = /filename\*?=(?:UTF-8'')?"?([^";]+)"?/i.exec(cd);
  return m ? decodeURIComponent(m[1]) : fallback;
}
