// How a checkpoint was made: its header's lineage (GET /api/v1/checkpoints/{id}/lineage), one
// row per training run that led to it, oldest first; the job spec behind each row.
import { el, errorBox, fmtNum, getJson } from './api.js';

/** A "How made" button that shows checkpoint `checkpoint`'s lineage in `target`. */
export function lineageButton(checkpoint, target) {
  return el('button', { type: 'button', class: 'small', onclick: () => showLineage(checkpoint, target) }, 'How made');
}

async function showLineage(checkpoint, target) {
  let body;
  try {
    body = await getJson(`/api/v1/checkpoints/${checkpoint.id}/lineage`);
  } catch (err) {
    return target.replaceChildren(errorBox(err));
  }
  const heading = el('h2', {}, `How checkpoint ${checkpoint.id} was made`);
  if (!body.lineage.length) {
    return target.replaceChildren(heading,
      el('p', { class: 'muted' }, 'Its header records no lineage (written before checkpoints kept one).'));
  }
  const short = (hash) => (hash ? el('code', { title: hash }, hash.slice(0, 12)) : '');
  const rows = body.lineage.map((stage, k) => el('tr', { 'data-stage': k + 1 },
    el('td', {}, k + 1), el('td', {}, stage.kind), el('td', {}, stage.algorithm),
    el('td', {}, stage.steps.toLocaleString()), el('td', {}, fmtNum(stage.wall_s / 60, 1)),
    el('td', {}, stage.seed), el('td', {}, stage.world || ''),
    el('td', {}, short(stage.world_hash), stage.corrections ? el('details', {}, el('summary', {}, 'grasp corrections'),
      el('code', {}, stage.corrections.command), el('pre', {}, JSON.stringify(stage.corrections.offsets, null, 2))) : ''),
    el('td', {}, short(stage.parent_sha256)),
    el('td', {}, stage.imitation ? el('code', {}, JSON.stringify(stage.imitation)) : ''),
    el('td', {}, stage.command ? el('code', {}, stage.command.join(' ')) : '',
      stage.job ? el('details', {}, el('summary', {}, 'job spec'), el('pre', {}, JSON.stringify(stage.job, null, 2))) : '')));
  target.replaceChildren(heading, el('table', { id: 'lineage' }, el('thead', {}, el('tr', {},
    ['stage', 'kind', 'algorithm', 'steps', 'minutes', 'seed', 'world', 'world hash', 'parent sha256', 'behaviour cloning', 'command']
      .map((h) => el('th', {}, h)))), el('tbody', {}, ...rows)));
}
