// The operator page: buttons send the `ips` commands through POST /api/command; everything shown
// comes from the service through GET /api/events (server-sent events), so another client's
// changes appear here without a reload.
import { createTwin } from './twin.js';

const $ = (id) => document.getElementById(id);
// Rounded first, so that a residual of -0.0001 mm reads 0.000, not -0.000.
const mm = (m) => (Math.round(m * 1e6) / 1000 + 0).toFixed(3);
const deg = (rad) => (rad * 180 / Math.PI).toFixed(2);
const vec = (v, digits = 1) => '(' + v.map((x) => x.toFixed(digits)).join(', ') + ')';

const page = {
  status: null,
  state: null,
  selected: new Set(),
  endpoints: null,
  lastError: null,
  busy: false,
};

let twin = null;
try {
  twin = createTwin($('twin'));
} catch (error) {
  // No WebGL (an old tablet, a locked-down browser): the page works without its twin.
  page.lastError = 'The 3D view is not available here: ' + error.message;
}

async function send(command, ids) {
  const body = { command };
  if (ids) body.ids = ids;
  const response = await fetch('api/command', {
    method: 'POST',
    headers: { 'Content-Type': 'application/json' },
    body: JSON.stringify(body),
  });
  const reply = await response.json().catch(() => ({ ok: false, reason: response.statusText }));
  if (!response.ok || !reply.ok) throw new Error(reply.reason || ('HTTP ' + response.status));
  return reply.data;
}

async function press(command) {
  if (page.busy) return;
  let ids;
  if (command === 'remove') {
    ids = [...page.selected];
    if (ids.length === 0) {
      page.lastError = 'Select the inspections to remove first (tap them in the list).';
      renderMessages();
      return;
    }
  }
  if (command === 'reset' && !window.confirm('Remove every inspection?')) return;
  page.busy = true;
  document.querySelectorAll('button[data-command]').forEach((b) => { b.disabled = true; });
  try {
    const data = await send(command, ids);
    page.lastError = null;
    if (command === 'remove' || command === 'reset') page.selected.clear();
    if (command === 'get' && data.note) page.lastError = 'Touch ' + data.id + ': ' + data.note;
  } catch (error) {
    page.lastError = command + ': ' + error.message;
  } finally {
    page.busy = false;
    document.querySelectorAll('button[data-command]').forEach((b) => { b.disabled = false; });
    renderMessages();
  }
}

async function removeOne(id) {
  try {
    await send('remove', [id]);
    page.selected.delete(id);
    page.lastError = null;
  } catch (error) {
    page.lastError = 'remove ' + id + ': ' + error.message;
  }
  renderMessages();
}

function renderConnection() {
  const doc = page.status;
  const service = $('service-state');
  const mirroring = $('mirroring-state');
  const age = $('sample-age');
  const connected = doc && doc.connected;
  // The endpoints stay as last told while the page server itself is out of reach.
  if (doc && doc.endpoints) page.endpoints = doc.endpoints;
  const ends = page.endpoints;
  $('endpoints').textContent = ends ? 'service ' + ends.service + ', bridge ' + ends.bridge_rep + ' / ' + ends.bridge_pub : '';
  service.textContent = connected ? 'service: connected' : 'service: no answer';
  service.className = 'pill ' + (connected ? 'ok' : 'bad');
  const status = connected ? doc.status : null;
  mirroring.textContent = status ? (status.mirroring ? 'robot: mirroring' : 'robot: not mirroring') : 'robot: ?';
  mirroring.className = 'pill ' + (status && status.mirroring ? 'ok' : '');
  if (status && status.sample_age_s !== null && status.sample_age_s !== undefined) {
    age.textContent = 'sample: ' + (status.sample_age_s * 1000).toFixed(0) + ' ms old';
  } else {
    age.textContent = 'sample: none yet';
  }
  age.className = 'pill ' + (status && !status.stale ? 'ok' : 'bad');
  $('kinematics').textContent = status && status.kinematics ? 'kinematics: ' + status.kinematics : '';
}

function guidance() {
  const doc = page.status;
  if (!doc || !doc.connected) return 'The alignment service does not answer' + (doc && doc.error ? ': ' + doc.error : '.');
  const status = doc.status;
  const count = page.state ? page.state.inspections.length : status.inspections;
  if (!status.mirroring) return 'Start mirroring: press Start.';
  if (status.stale) return 'Mirroring, but no fresh joint state: is the robot connected to the bridge?';
  const lines = [];
  const next = page.state && page.state.results ? page.state.results.next_touch : null;
  if (next) {
    lines.push('Take a touch: next suggested at ' + vec(next.point_mm) + ' mm, approach ' +
      vec(next.approach, 2) + ', tilt ' + next.tilt_deg.toFixed(0) + '°: ' + next.reason);
  } else {
    lines.push('Take a touch: bring the ball onto the part, let the robot rest, press Get.');
  }
  if (count >= 6) lines.push(count + ' touches: enough to Align (and Diagnose).');
  else lines.push(count + ' touches so far; 6 or more spread over the part (3-2-1) are advised before Align.');
  return lines.join('\n');
}

function renderMessages() {
  const box = $('messages');
  box.replaceChildren();
  for (const line of guidance().split('\n')) {
    const p = document.createElement('p');
    p.textContent = line;
    box.append(p);
  }
  if (page.lastError) {
    const p = document.createElement('p');
    p.className = 'error';
    p.textContent = page.lastError;
    box.append(p);
  }
}

function describeResult(result) {
  const report = result.report;
  if (result.command === 'align') {
    const p = report.pose;
    const lines = [
      'Alignment of ' + result.inspections.length + ' touches: rms ' + mm(report.rms) + ' mm, max ' + mm(report.max) + ' mm' +
        (report.converged ? '' : ' (not converged)'),
      'part pose (base frame): xyz ' + vec(p.xyz.map((x) => x * 1000), 2) + ' mm, rpy (' + p.rpy.map(deg).join(', ') + ') deg',
    ];
    const uncertainty = report.uncertainty;
    if (uncertainty && uncertainty.pose_distance_95_mm != null) {
      lines.push('within ' + uncertainty.pose_distance_95_mm.toFixed(3) + ' mm of the truth at 95% confidence; ' +
        uncertainty.weak_direction.text);
    } else if (report.uncertainty_error) {
      lines.push('pose uncertainty not available: ' + report.uncertainty_error);
    }
    if (report.ambiguous) lines.push('Ambiguous: other poses fit as well; take the suggested touch.');
    return lines.join('\n');
  }
  const lines = [
    'Diagnosis: ' + report.verdict + (report.effect ? ' (' + report.effect.name + ')' : ''),
    'rms before ' + mm(report.before.rms) + ' mm, after ' + mm(report.after.rms) + ' mm',
  ];
  if (report.effect) {
    for (const [name, value] of Object.entries(report.effect.params || {})) {
      lines.push('  ' + name + ' = ' + (Array.isArray(value) ? vec(value, 6) : Number(value).toPrecision(6)));
    }
  }
  return lines.join('\n');
}

// The newer (by the service's serial) of its latest alignment and diagnosis, whoever asked.
function latestResult(state) {
  const results = (state && state.results) || {};
  const found = [];
  if (results.alignment) found.push({ command: 'align', ...results.alignment });
  if (results.diagnosis) found.push({ command: 'diagnose', ...results.diagnosis });
  found.sort((a, b) => b.serial - a.serial);
  return found[0] || null;
}

function renderResult() {
  const box = $('result');
  const result = latestResult(page.state);
  if (!result) {
    box.textContent = 'No alignment yet: take touches, then press Align.';
    box.classList.remove('stale');
  } else {
    box.textContent = describeResult(result) +
      (result.current ? '' : '\n(the inspections changed since: press ' + (result.command === 'align' ? 'Align' : 'Diagnose') + ' again)');
    box.classList.toggle('stale', !result.current);
  }
  renderDiagnosis();
}

// The service's latest diagnosis as the page server drew it (the same charts and tables as the
// report `ips diagnose` writes; every text in it escaped there).
let shownDiagnosis = null;
function renderDiagnosis() {
  const panel = $('diagnosis-panel');
  const state = page.state;
  const diagnosis = state && state.results ? state.results.diagnosis : null;
  panel.hidden = !diagnosis || !state.diagnosis_html;
  if (panel.hidden) { shownDiagnosis = null; return; }
  const report = diagnosis.report;
  $('diagnosis-summary').textContent = report.verdict + (report.effect && report.verdict === 'effect' ? ' (' + report.effect.name + ')' : '') +
    ', rms ' + mm(report.before.rms) + ' → ' + mm(report.after.rms) + ' mm' + (diagnosis.current ? '' : ' (inspections changed since)');
  panel.classList.toggle('stale', !diagnosis.current);
  if (shownDiagnosis !== state.diagnosis_html) {
    $('diagnosis').innerHTML = state.diagnosis_html;
    // A new diagnosis opens itself; the operator may close it.
    if (shownDiagnosis !== null || latestResult(state).command === 'diagnose') panel.open = true;
    shownDiagnosis = state.diagnosis_html;
  }
}

function residuals(state) {
  const byId = new Map();
  const result = latestResult(state);
  if (!result || !result.current) return byId;
  if (result.command === 'align') {
    for (const r of result.report.residuals || []) byId.set(r.id, r.distance);
  } else {
    for (const r of result.report.inspections || []) byId.set(r.id, r.residual_after);
  }
  return byId;
}

function renderInspections() {
  const list = $('inspections');
  const state = page.state;
  const touches = new Map((state.touches || []).map((t) => [t.id, t]));
  const byId = residuals(state);
  $('count').textContent = '(' + state.inspections.length + ')';
  const present = new Set(state.inspections.map((i) => i.id));
  for (const id of [...page.selected]) if (!present.has(id)) page.selected.delete(id);
  list.replaceChildren();
  for (const inspection of state.inspections) {
    const item = document.createElement('li');
    item.dataset.inspectionId = inspection.id;
    item.classList.toggle('selected', page.selected.has(inspection.id));
    const id = document.createElement('span');
    id.className = 'id';
    id.textContent = inspection.id;
    const detail = document.createElement('span');
    detail.className = 'detail';
    const touch = touches.get(inspection.id);
    let text = touch ? 'ball ' + vec(touch.ball_centre_m.map((x) => x * 1000)) + ' mm' : 'flange pose';
    if (byId.has(inspection.id)) text += ', residual ' + mm(byId.get(inspection.id)) + ' mm';
    if (inspection.trigger) text += ' (trigger ' + inspection.trigger + ')';
    detail.textContent = text;
    const remove = document.createElement('button');
    remove.type = 'button';
    remove.className = 'remove';
    remove.textContent = '✕';
    remove.setAttribute('aria-label', 'Remove inspection ' + inspection.id);
    remove.addEventListener('click', (event) => { event.stopPropagation(); removeOne(inspection.id); });
    item.addEventListener('click', () => {
      if (page.selected.has(inspection.id)) page.selected.delete(inspection.id);
      else page.selected.add(inspection.id);
      item.classList.toggle('selected');
    });
    item.append(id, detail, remove);
    list.append(item);
  }
}

function connect() {
  const events = new EventSource('api/events');
  events.addEventListener('status', (event) => {
    page.status = JSON.parse(event.data);
    renderConnection();
    renderMessages();
  });
  events.addEventListener('state', (event) => {
    const state = JSON.parse(event.data);
    if (!state) return;
    page.state = state;
    renderInspections();
    renderResult();
    renderMessages();
    if (twin) twin.setState(state, residuals(state), latestResult(state));
  });
  events.addEventListener('robot', (event) => {
    const robot = JSON.parse(event.data);
    if (twin && robot) twin.setRobot(robot);
  });
  events.onerror = () => {
    // EventSource reconnects by itself; say so meanwhile.
    page.status = { connected: false, error: 'lost the page server (reconnecting)' };
    renderConnection();
    renderMessages();
  };
}

for (const button of document.querySelectorAll('button[data-command]')) {
  button.addEventListener('click', () => press(button.dataset.command));
}
renderMessages();
if (twin) {
  fetch('api/scene').then((r) => r.json()).then((scene) => twin.setScene(scene))
    .catch((error) => { page.lastError = 'scene: ' + error.message; renderMessages(); });
}
connect();
