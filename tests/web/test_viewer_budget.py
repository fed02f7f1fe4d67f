"""The viewer with inputs of a million points: decimated for display only, and said so.

The inputs are made in the page (as POST /v1/info?preview=true would answer them) so that the
test measures the browser side alone; the server side of large inputs is the engine's.
"""

from __future__ import annotations

from typing import Any

from tests.timing import load_factor
from tests.web.web_helpers import Browsing, WebServer, nonblank_fraction

PANE_BACKGROUND = (0xEC, 0xEE, 0xF3)

SHOW_SYNTHETIC = """async ([n, mesh]) => {
  const { showInputView } = await import('/static/js/compare.js');
  const { BUDGETS } = await import('/static/js/geometry.js');
  let pos, faces = null;
  if (mesh) {  // an m x m height field
    const m = Math.round(Math.sqrt(n)); n = m * m;
    pos = new Float32Array(n * 3);
    for (let i = 0; i < m; i++) for (let j = 0; j < m; j++) {
      const k = 3 * (i * m + j);
      pos[k] = i / m - 0.5; pos[k + 1] = j / m - 0.5;
      pos[k + 2] = 0.05 * Math.sin(10 * i / m) * Math.cos(7 * j / m);
    }
    faces = new Uint32Array((m - 1) * (m - 1) * 6);
    let f = 0;
    for (let i = 0; i < m - 1; i++) for (let j = 0; j < m - 1; j++) {
      const a = i * m + j, b = a + 1, c = a + m, d = c + 1;
      faces.set([a, b, d, a, d, c], f); f += 6;
    }
  } else {  // a torus cloud
    pos = new Float32Array(n * 3);
    for (let i = 0; i < n; i++) {
      const u = (i * 2.399963) % 6.2832, v = (i * 0.618034 * 6.2832) % 6.2832;
      const r = 1 + 0.35 * Math.cos(v);
      pos[3 * i] = r * Math.cos(u); pos[3 * i + 1] = r * Math.sin(u);
      pos[3 * i + 2] = 0.35 * Math.sin(v);
    }
  }
  const b64 = (a) => {
    const u = new Uint8Array(a.buffer); let s = '';
    for (let i = 0; i < u.length; i += 32768) {
      s += String.fromCharCode.apply(null, u.subarray(i, i + 32768));
    }
    return btoa(s);
  };
  const preview = { origin: [0, 0, 0], n_points: n, dimension: 3, positions: b64(pos),
    faces: faces ? b64(faces) : null, segments: null };
  const info = { kind: mesh ? 'mesh' : 'cloud', preview };
  const start = performance.now();
  const { plan, viewer } = showInputView(info);
  const seconds = (performance.now() - start) / 1000;
  const budget = BUDGETS[viewer.software ? 'software' : 'gpu'];
  let maxIndex = 0;
  if (plan.faces) for (const i of plan.faces) if (i > maxIndex) maxIndex = i;
  return { n, shown: plan.keep.length, faces: plan.faces ? plan.faces.length / 3 : 0,
    decimated: plan.decimated, budget, maxIndex, seconds, software: viewer.software,
    note: document.getElementById('viewer-note').textContent };
}"""


def show(page: Any, n: int, mesh: bool) -> dict[str, Any]:
    out: dict[str, Any] = page.evaluate(SHOW_SYNTHETIC, [n, mesh])
    assert out["decimated"], out
    assert out["shown"] <= out["budget"][0] and out["faces"] <= out["budget"][1]
    assert "Decimated for display only" in out["note"] and f"of {out['n']:,} points" in out["note"]
    # a hang guard (the decimation is what keeps the page responsive, checked above): 20 s on
    # a quiet machine, per unit of the load on a busy one
    assert out["seconds"] < 20 * load_factor(), out
    page.wait_for_timeout(100)
    fraction = nonblank_fraction(page.locator("#pane-before canvas").screenshot(), PANE_BACKGROUND)
    assert fraction > 0.05, fraction
    return out


def test_a_million_points_are_decimated_for_display(
    browsing: Browsing, web_server: WebServer
) -> None:
    page = browsing.page
    page.goto(f"{web_server.url}/")
    page.wait_for_selector("body[data-ready=true]")
    cloud = show(page, 1_000_000, mesh=False)
    assert cloud["faces"] == 0 and cloud["shown"] >= cloud["budget"][0] // 2
    browsing.shot("12-million-point-cloud")
    mesh = show(page, 400_000, mesh=True)  # above both budgets (300,000 and 60,000 vertices)
    assert mesh["faces"] > 0 and mesh["maxIndex"] < mesh["shown"]  # remapped connectivity
    browsing.shot("13-large-mesh-decimated")
    browsing.assert_offline()
