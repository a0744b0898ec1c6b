// Models: checkpoints no job here trained (the shipped models, registered when the
// coordinator starts on a new data folder, and uploads): their facts, download, Evaluate,
// their evaluations, and an upload form.
import { el, errorBox, fmtBytes, fmtTime, getJson, onChange, sendBytes } from './api.js';
import { lineageButton } from './lineage.js';
import { evaluationTable, queueEvaluation } from './run.js';

export async function renderModels(main) {
  document.title = 'Models · crm-grasp';
  const message = el('div', { class: 'message', role: 'status' });
  const rows = el('tbody');
  const evaluations = el('div');
  const lineage = el('section', { id: 'lineage-view' });
  const episodesInput = el('input', { type: 'text', inputmode: 'numeric', value: '100', name: 'eval-episodes', size: 6 });
  const meanInput = el('input', { type: 'checkbox', name: 'eval-deterministic' });
  const fileInput = el('input', { type: 'file', id: 'model-file', accept: '.safetensors' });
  const uploadButton = el('button', { type: 'button', id: 'upload-model', onclick: () => upload() }, 'Upload');

  main.replaceChildren(
    el('h1', {}, 'Models'),
    el('p', { class: 'muted' }, 'Policy checkpoints made elsewhere: the shipped models in ', el('code', {}, 'models/'),
      ' and uploads (here, ', el('code', {}, 'POST /api/v1/checkpoints'), ' or ',
      el('code', {}, 'crm eval --coordinator URL --checkpoint FILE'), '). The same file uploaded twice is one model.'),
    el('div', { class: 'toolbar' }, el('label', {}, 'checkpoint file ', fileInput), ' ', uploadButton),
    message,
    el('p', { class: 'muted' }, 'Evaluate with ', episodesInput, ' episodes (',
      el('label', {}, meanInput, ' deterministic action instead of sampled'), '); the result appears under Evaluations.'),
    el('table', { id: 'models' }, el('thead', {}, el('tr', {},
      ['id', 'name', 'algorithm', 'trained steps', 'size', 'added', 'sha256', ''].map((h) => el('th', {}, h)))), rows),
    lineage,
    el('h2', {}, 'Evaluations'), evaluations);

  const showError = (err) => message.replaceChildren(errorBox(err.field ? new Error(`${err.field}: ${err.message}`) : err));

  async function upload() {
    const file = fileInput.files[0];
    if (!file) return showError(new Error('Choose a .safetensors checkpoint file first.'));
    try {
      const name = file.name.replace(/\.safetensors$/, '');
      const row = await sendBytes('POST', `/api/v1/checkpoints?name=${encodeURIComponent(name)}`, await file.arrayBuffer());
      message.replaceChildren(el('div', { class: 'ok', id: 'uploaded' }, `Stored as model ${row.id} (${row.name || row.algorithm}).`));
      refresh();
    } catch (err) {
      showError(err);
    }
  }

  async function refresh() {
    let list;
    let evals;
    try {
      [list, evals] = await Promise.all([getJson('/api/v1/checkpoints?uploaded=true'), getJson('/api/v1/evaluations')]);
    } catch (err) {
      return showError(err);
    }
    const ids = new Set(list.checkpoints.map((c) => c.id));
    rows.replaceChildren(...list.checkpoints.map((c) => el('tr', { 'data-checkpoint': c.id },
      el('td', {}, c.id), el('td', {}, c.name || ''), el('td', {}, c.algorithm), el('td', {}, c.steps.toLocaleString()),
      el('td', {}, fmtBytes(c.size)), el('td', {}, fmtTime(c.created_at)),
      el('td', {}, el('code', { title: c.sha256 || '' }, (c.sha256 || '').slice(0, 12))),
      el('td', {}, el('a', { href: `/api/v1/checkpoints/${c.id}/download`, class: 'button small', download: true }, 'Download'), ' ',
        el('button', { type: 'button', class: 'small', onclick: () => queueEvaluation(c, episodesInput, meanInput, message) }, 'Evaluate'), ' ',
        lineageButton(c, lineage)))));
    if (!list.checkpoints.length) {
      rows.append(el('tr', {}, el('td', { colspan: 8, class: 'muted' }, 'No model yet: upload a checkpoint above.')));
    }
    evaluations.replaceChildren(evaluationTable(evals.evaluations.filter((e) => ids.has(e.checkpoint_id))));
  }

  refresh();
  onChange(refresh);
}
