"""The page's own modules in the browser, on inputs the live server does not produce (yet):
event streams cut at every byte, and schema shapes the parameters may take."""

from __future__ import annotations

from tests.web.web_helpers import Browsing, WebServer

SSE_EVERY_SPLIT = """async () => {
  const { parseEventStream } = await import('/static/js/sse.js');
  const text = 'id: 1\\r\\nevent: status\\r\\ndata: {"a":1}\\r\\n\\r\\n: ping\\n\\n'
    + 'id: 2\\nevent: progress\\ndata: {"b":\\ndata: 2}\\n\\nid: 3\\rdata:x\\r\\r';
  const runs = [];
  for (let cut = 0; cut <= text.length; cut++) {
    const seen = [];
    const feed = parseEventStream((e) => seen.push(e));
    feed(text.slice(0, cut)); feed(text.slice(cut)); feed('\\n\\n');
    runs.push(JSON.stringify(seen));
  }
  return { distinct: [...new Set(runs)], first: runs[0] };
}"""

FORM_FROM_SCHEMA = """async () => {
  const { SchemaForm } = await import('/static/js/schemaform.js');
  const root = { components: { schemas: {
    Mode: { enum: ['a', 'b'], type: 'string', description: 'mode' },
    P: { type: 'object', properties: {
      tau: { anyOf: [{ type: 'number', exclusiveMinimum: 0 },
                     { enum: ['auto', 'gcv'], type: 'string' }, { type: 'null' }],
             default: null, description: 'tau or a rule' },
      k: { type: 'integer', minimum: 3, maximum: 64, default: 12, description: 'neighbours' },
      mode: { $ref: '#/components/schemas/Mode', default: 'a' },
      flag: { type: 'boolean', default: false },
    } } } } };
  const box = document.createElement('div');
  document.body.append(box);
  const form = new SchemaForm(box, root.components.schemas.P, root);
  const out = { initial: form.values() };
  form.set('tau', 'gcv'); form.set('mode', 'b'); form.set('flag', true);
  out.words = form.values();
  form.set('tau', '0.25'); form.set('k', '12');
  out.numbers = form.values();
  out.tauInput = box.querySelector('#param-tau').getAttribute('list');
  out.kInput = [box.querySelector('#param-k').type, box.querySelector('#param-k').min,
                box.querySelector('#param-k').max];
  out.groups = [...box.querySelectorAll('.pform')].map((g) => g.querySelectorAll('label').length);
  out.help = box.querySelector('[data-field="params.k"] .help').textContent;
  box.remove();
  return out;
}"""


def test_event_stream_parser_at_every_split(browsing: Browsing, web_server: WebServer) -> None:
    page = browsing.page
    page.goto(f"{web_server.url}/")
    page.wait_for_selector("body[data-ready=true]")
    out = page.evaluate(SSE_EVERY_SPLIT)
    assert len(out["distinct"]) == 1, out["distinct"]  # the same events wherever it is cut
    assert out["first"] == (
        '[{"type":"status","data":"{\\"a\\":1}","id":"1"},'
        '{"type":"progress","data":"{\\"b\\":\\n2}","id":"2"},'
        '{"type":"message","data":"x","id":"3"}]'
    )


def test_form_generated_from_schema_shapes(browsing: Browsing, web_server: WebServer) -> None:
    page = browsing.page
    page.goto(f"{web_server.url}/")
    page.wait_for_selector("body[data-ready=true]")
    out = page.evaluate(FORM_FROM_SCHEMA)
    assert out["initial"] == {}  # defaults are not sent
    assert out["words"] == {"tau": "gcv", "mode": "b", "flag": True}
    assert out["numbers"] == {"tau": 0.25, "mode": "b", "flag": True}  # k = default: left out
    assert out["tauInput"] == "param-tau-list"  # a number or one of the words
    assert out["kInput"] == ["number", "3", "64"]
    assert out["groups"] == [1, 3]  # the alternatives (default null) first, then the rest
    assert "neighbours" in out["help"] and "≥ 3" in out["help"] and "default 12" in out["help"]
    browsing.assert_offline()


BBOX_AND_LABELS = """async () => {
  const { bboxText } = await import('/static/js/ui.js');
  const { LABELS } = await import('/static/js/schemaform.js');
  const labels = [...document.querySelectorAll('#params-section label.label')]
    .map((l) => l.textContent);
  return {
    utm: bboxText({ min: [500000.009, 5000000.003, 9.161], max: [500110.0, 5000109.997, 10.842] }),
    small: bboxText({ min: [-1, 0, 0.5], max: [1, 2, 1.5] }),
    labels, tau: LABELS.tau,
  };
}"""


def test_utm_bounds_show_the_offset_once_and_labels_are_words(
    browsing: Browsing, web_server: WebServer
) -> None:
    """Issue 41 item 7: a 110 m UTM extent reads as ranges about a round offset, not
    "[500,000, 5.001e+5]"; the form's labels are words with units, not "Lam", "Tau"."""
    page = browsing.page
    page.goto(f"{web_server.url}/")
    page.wait_for_selector("body[data-ready=true]")
    out = page.evaluate(BBOX_AND_LABELS)
    assert out["utm"] == (
        "offset (500,000, 5,000,000, 0); [0.009, 110] × [0.003, 110] × [9.161, 10.84]"
    ), out["utm"]
    assert out["small"] == "[-1, 1] × [0, 2] × [0.5, 1.5]"
    assert "τ: deviation budget (units²)" in out["labels"] and "Tau" not in out["labels"]
    assert "Lam" not in out["labels"] and out["tau"] == "τ: deviation budget (units²)"
