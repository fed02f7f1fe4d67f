// A parameter form generated at runtime from a JSON schema (SmoothingParams in /openapi.json):
// input types, defaults, bounds, enums, titles and help text all come from the schema.
// Fields whose default is null (the alternatives: tau, rms, lam) form the first group;
// fields that have defaults go under "more parameters".

function resolve(schema, root) {
  let s = schema;
  for (let guard = 0; s && s.$ref && guard < 10; guard++) {
    const path = s.$ref.replace(/^#\//, "").split("/");
    s = path.reduce((node, key) => (node ? node[key] : undefined), root);
  }
  if (s && Array.isArray(s.allOf) && s.allOf.length === 1) return { ...resolve(s.allOf[0], root), ...s, allOf: undefined };
  return s || {};
}

/** The field's alternatives without null: [{type, enum, minimum, ...}], and whether null is allowed. */
function variants(prop, root) {
  const alts = (prop.anyOf || prop.oneOf || [prop]).map((a) => resolve(a, root));
  const nullable = alts.some((a) => a.type === "null" || (a.enum && a.enum.includes(null)));
  return { alts: alts.filter((a) => a.type !== "null"), nullable };
}

function describeBounds(alt) {
  const parts = [];
  if (alt.exclusiveMinimum !== undefined) parts.push(`> ${alt.exclusiveMinimum}`);
  if (alt.minimum !== undefined) parts.push(`≥ ${alt.minimum}`);
  if (alt.exclusiveMaximum !== undefined) parts.push(`< ${alt.exclusiveMaximum}`);
  if (alt.maximum !== undefined) parts.push(`≤ ${alt.maximum}`);
  return parts.join(", ");
}

function el(tag, attrs = {}, ...children) {
  const node = document.createElement(tag);
  for (const [k, v] of Object.entries(attrs)) {
    if (v === undefined || v === null || v === false) continue;
    if (k === "class") node.className = v; else if (k === "text") node.textContent = v;
    else node.setAttribute(k, v === true ? "" : v);
  }
  for (const c of children) if (c) node.append(c);
  return node;
}

/** One control for a property: returns {node, read(), write(v)}. */
function control(name, prop, root) {
  const { alts, nullable } = variants(prop, root);
  const enums = alts.flatMap((a) => a.enum || (a.const !== undefined ? [a.const] : []));
  const numeric = alts.find((a) => a.type === "number" || a.type === "integer");
  const boolean = alts.find((a) => a.type === "boolean");
  const id = `param-${name}`;
  if (boolean && alts.length === 1) {
    const input = el("input", { type: "checkbox", id, name });
    return { node: input, read: () => input.checked, write: (v) => { input.checked = !!v; } };
  }
  if (enums.length && !numeric) {
    const select = el("select", { id, name });
    if (nullable) select.append(el("option", { value: "", text: "—" }));
    for (const v of enums) select.append(el("option", { value: String(v), text: String(v) }));
    return { node: select, read: () => (select.value === "" ? null : select.value), write: (v) => { select.value = v ?? ""; } };
  }
  if (numeric) {
    // A number, possibly also one of a few words (e.g. tau = "gcv"): a text box with suggestions.
    const attrs = { id, name, inputmode: "decimal", autocomplete: "off", placeholder: nullable ? "—" : "" };
    const input = el("input", enums.length ? { ...attrs, type: "text", list: `${id}-list` } : { ...attrs, type: "number", step: "any",
      min: numeric.minimum ?? numeric.exclusiveMinimum, max: numeric.maximum ?? numeric.exclusiveMaximum });
    const wrap = el("span", {}, input);
    if (enums.length) {
      const list = el("datalist", { id: `${id}-list` });
      for (const v of enums) list.append(el("option", { value: String(v) }));
      wrap.append(list);
    }
    const read = () => {
      const text = input.value.trim();
      if (text === "") return null;
      if (enums.includes(text)) return text;
      const value = Number(text);
      return Number.isFinite(value) ? value : text; // the server names what is wrong with text
    };
    return { node: wrap, input, read, write: (v) => { input.value = v === null || v === undefined ? "" : String(v); } };
  }
  const input = el("input", { type: "text", id, name });
  return { node: input, read: () => input.value || null, write: (v) => { input.value = v ?? ""; } };
}

/**
 * Human labels with units for the parameters (issue 41: not the schema's "Lam", "Tau"); a
 * parameter not named here keeps the schema's title. "units" are the input's coordinate units
 * (metres for GPX/GeoJSON and projected scans).
 */
export const LABELS = {
  tau: "τ: deviation budget (units²)",
  rms: "RMS displacement (units)",
  lam: "λ: smoothing weight",
  laplacian: "Laplacian",
  weights: "neighbour weights",
  neighborhood: "point neighbourhoods",
  k: "k: neighbours",
  sigma_h: "σ_h: Laplacian regularisation",
  sigma_f: "σ_f: feature scale",
  robust: "robust (outlier-resistant) weights",
  noise_weights: "weights from the noise",
  outliers: "outliers",
  tolerance: "relative tolerance of τ",
  max_iterations: "maximum λ iterations",
  fix_boundary: "hold the boundary fixed",
  preserve_volume: "preserve the volume",
  solver: "linear solver",
  search: "λ search",
  method: "method",
  order: "order",
  spectrum: "spectrum report",
  displacement: "displacement",
  tangential: "tangential step",
  presmooth: "pre-smoothing passes",
  junctions: "curve junctions",
  ends: "curve ends",
  boundary: "boundary",
  max_deviation: "maximum deviation (units)",
  strict: "strict: fail on shape loss",
  tile_points: "points per tile",
  preset: "preset",
};

export class SchemaForm {
  /**
   * @param {HTMLElement} container where the fields go
   * @param {object} schema the object schema (e.g. components.schemas.SmoothingParams)
   * @param {object} root the document $refs resolve against (the whole OpenAPI spec)
   */
  constructor(container, schema, root) {
    this.schema = resolve(schema, root);
    this.root = root;
    this.fields = new Map();
    container.replaceChildren(this.build());
  }

  build() {
    const props = Object.entries(this.schema.properties || {});
    const isAlternative = ([, p]) => p.default === null && variants(p, this.root).nullable;
    const first = el("div", { class: "pform" }, el("div", { class: "pgroup-title", text: "Target (give one)" }));
    const more = el("div", { class: "pform" });
    for (const entry of props) (isAlternative(entry) ? first : more).append(...this.row(...entry));
    const details = el("details", { class: "more" }, el("summary", { text: "more parameters" }), more);
    return el("div", {}, first, details);
  }

  row(name, prop) {
    const c = control(name, prop, this.root);
    const def = prop.default;
    if (def !== undefined) c.write(def);
    const { alts } = variants(prop, this.root);
    const bounds = alts.map(describeBounds).filter(Boolean).join("; ");
    const label = el("label", { class: "label", for: `param-${name}`, text: LABELS[name] || prop.title || name });
    const help = el("div", { class: "help", text: [prop.description, bounds && `(${bounds})`,
      def !== undefined && def !== null ? `default ${def}` : ""].filter(Boolean).join(" ") });
    const range = el("span", { class: "range", "data-range-for": name });
    const error = el("div", { class: "field-error", "data-error-for": `params.${name}` });
    const cell = el("div", { class: "control", "data-field": `params.${name}` }, c.node, range, help, error);
    this.fields.set(name, { ...c, prop, cell });
    return [label, cell];
  }

  /** The parameters to send: every field whose value is set and differs from its default. */
  values() {
    const out = {};
    for (const [name, f] of this.fields) {
      const v = f.read();
      if (v === null || v === undefined) continue;
      if (f.prop.default !== undefined && v === f.prop.default) continue;
      out[name] = v;
    }
    return out;
  }

  set(name, value) { this.fields.get(name)?.write(value); }
  get(name) { return this.fields.get(name)?.read(); }
  has(name) { return this.fields.has(name); }

  /** A hint next to a field, e.g. the valid range of tau for the input read. */
  setHint(name, text) {
    const node = this.fields.get(name)?.cell.querySelector("[data-range-for]");
    if (node) node.textContent = text || "";
  }

  focus(name) {
    const f = this.fields.get(name);
    (f?.input || f?.node)?.focus?.();
  }
}
