// Sweeps: the list, and one sweep's page: progress, training curves as a mean ± std band per
// configuration, Table I aggregated over seeds with the best cells in bold, its jobs, and a
// link to the compare page with all its runs.
import {
  ApiError, badge, chartControls, chartSettings, drawChart, el, errorBox, fmtNum, fmtTime, getJson,
  notFound, onChange, send,
} from './api.js';

const METRICS = ['success', 'episode_length'];

export async function renderSweeps(main) {
  document.title = 'Sweeps · crm-grasp';
  const body = el('div');
  main.replaceChildren(el('h1', {}, 'Sweeps'),
    el('p', { class: 'muted' }, 'A grid of training runs (algorithms, seeds, any config key) with an evaluation of every final checkpoint: ',
      el('code', {}, 'POST /api/v1/sweeps'), ' or ', el('code', {}, 'crm results --coordinator URL'), '.'),
    body);
  async function refresh() {
    try {
      const { sweeps } = await getJson('/api/v1/sweeps');
      body.replaceChildren(sweeps.length
        ? el('table', { id: 'sweeps' }, el('thead', {}, el('tr', {}, ['id', 'name', 'axes', 'created'].map((h) => el('th', {}, h)))),
          el('tbody', {}, sweeps.map((s) => el('tr', { 'data-sweep': s.id },
            el('td', {}, el('a', { href: `/sweeps/${s.id}` }, `#${s.id}`)), el('td', {}, s.name),
            el('td', {}, Object.entries(s.spec.axes || {}).map(([k, v]) => `${k} × ${v.length}`).join(', ')),
            el('td', {}, fmtTime(s.created_at))))))
        : el('p', { class: 'muted' }, 'No sweep yet.'));
    } catch (err) {
      body.replaceChildren(errorBox(err));
    }
  }
  refresh();
  onChange(refresh);
}

export async function renderSweep(main, idText) {
  const id = Number(idText);
  if (!Number.isInteger(id) || id < 1) return notFound(main, `"${idText}" is not a sweep id.`);
  const header = el('section', { class: 'run-header' });
  const message = el('div', { class: 'message', role: 'status' });
  const figures = METRICS.map((metric) => el('figure', { class: 'chart', 'data-metric': metric }));
  const table = el('div', { id: 'table-one' });
  const jobs = el('div');
  const cancelButton = el('button', { type: 'button', id: 'cancel-sweep', class: 'danger', onclick: () => cancel() }, 'Cancel sweep');
  const compare = el('a', { class: 'button', id: 'compare-sweep' }, 'Compare its runs');
  let runs = [];
  const drawCharts = () => {
    if (!runs.length) return;
    const { smooth, x } = chartSettings();
    figures.forEach((figure) => drawChart(figure, {
      runs: runs.join(','), metric: figure.dataset.metric, smooth, x, group: 'seeds', width: 560, height: 300,
    }));
  };
  main.replaceChildren(header,
    el('div', { class: 'toolbar' }, chartControls(drawCharts), el('span', { class: 'spacer' }), compare, ' ', cancelButton),
    message, el('div', { class: 'charts' }, figures),
    el('h2', {}, 'Table I (mean ± std over seeds)'), table,
    el('h2', {}, 'Jobs'), jobs);

  async function cancel() {
    try {
      const done = await send('POST', `/api/v1/sweeps/${id}/cancel`);
      message.replaceChildren(el('div', { class: 'ok' }, `${done.cancelled} job${done.cancelled === 1 ? '' : 's'} cancelled.`));
    } catch (err) {
      message.replaceChildren(errorBox(err));
    }
  }

  async function refresh() {
    let d;
    try {
      d = await getJson(`/api/v1/sweeps/${id}`);
    } catch (err) {
      if (err instanceof ApiError && err.status === 404) return notFound(main, `Sweep ${id} does not exist.`);
      return message.replaceChildren(errorBox(err));
    }
    document.title = `Sweep ${id} · crm-grasp`;
    const p = d.progress;
    const open = d.jobs.some((j) => j.state === 'queued' || j.state === 'running');
    cancelButton.disabled = !open;
    header.replaceChildren(
      el('h1', {}, `Sweep #${id} `, el('small', {}, d.sweep.name)),
      el('div', { class: 'progress sweep', id: 'sweep-progress', title: `${p.finished} of ${p.jobs} jobs finished` },
        el('div', { class: 'bar', style: `width:${Math.round(100 * p.fraction)}%` }),
        el('span', {}, `${p.finished} of ${p.jobs} jobs finished (${p.succeeded} succeeded, ${p.failed} failed, ${p.cancelled} cancelled)`)),
      el('details', {}, el('summary', {}, 'request'), el('pre', {}, JSON.stringify(d.sweep.spec, null, 2))));
    const trainIds = d.jobs.filter((j) => j.kind === 'train').map((j) => j.id);
    compare.href = `/compare?runs=${trainIds.slice(0, 50).join(',')}`;
    const withCurves = d.jobs.filter((j) => j.kind === 'train' && j.state !== 'queued').map((j) => j.id);
    if (withCurves.join(',') !== runs.join(',')) {
      runs = withCurves;
      drawCharts();
    }
    if (!runs.length) figures.forEach((f) => f.replaceChildren(el('p', { class: 'muted' }, 'No run has started yet.')));
    table.replaceChildren(tableOne(d.table));
    jobs.replaceChildren(jobList(d.jobs));
  }
  refresh();
  onChange(refresh);
}

/** `mean ± std` of a cell, or a dash. */
function cell(stat, digits) {
  return stat && stat.n ? `${fmtNum(stat.mean, digits)} ± ${fmtNum(stat.std, digits)}` : '–';
}

/** Table I: one row per configuration; the best mean per column in bold, ties all bold
 * (highest success, shortest episodes). */
function tableOne(t) {
  if (!t.rows.length) return el('p', { class: 'muted' }, 'No runs.');
  const columns = [['overall', (r) => r.overall], ...t.objectives.map((o) => [o, (r) => r.per_objective[o]])];
  const best = (get, kind, better) => {
    const means = t.rows.map((r) => (get(r) && get(r)[kind].n ? get(r)[kind].mean : null));
    const known = means.filter((m) => m !== null);
    if (!known.length) return new Set();
    const top = known.reduce((a, b) => (better(a, b) ? a : b));
    return new Set(means.flatMap((m, k) => (m === top ? [k] : [])));
  };
  const marks = columns.map(([, get]) => ({
    success: best(get, 'success', (a, b) => a >= b),
    length: best(get, 'length', (a, b) => a <= b),
  }));
  return el('table', { id: 'sweep-table' },
    el('thead', {},
      el('tr', {}, el('th', { rowspan: 2 }, 'configuration'), el('th', { rowspan: 2 }, 'runs'), el('th', { rowspan: 2 }, 'early stop'),
        columns.map(([name]) => el('th', { colspan: 2 }, name))),
      el('tr', {}, columns.map(() => [el('th', {}, 'success'), el('th', {}, 'length')]))),
    el('tbody', {}, t.rows.map((r, k) => el('tr', { 'data-row': k },
      el('td', {}, r.label), el('td', {}, `${r.evaluated} of ${r.runs.length}`),
      el('td', {}, r.early_stop.runs ? `${r.early_stop.runs} (at ${r.early_stop.steps.map((s) => s.toLocaleString()).join(', ')})` : '0'),
      columns.map(([, get], c) => [
        el('td', { class: marks[c].success.has(k) ? 'best' : '' }, cell(get(r) && get(r).success, 2)),
        el('td', { class: marks[c].length.has(k) ? 'best' : '' }, cell(get(r) && get(r).length, 1)),
      ])))));
}

function jobList(list) {
  return el('table', { id: 'sweep-jobs' },
    el('thead', {}, el('tr', {}, ['id', 'kind', 'state', 'algorithm', 'seed', 'result'].map((h) => el('th', {}, h)))),
    el('tbody', {}, list.map((j) => el('tr', { 'data-job': j.id, 'data-state': j.state },
      el('td', {}, j.kind === 'train' ? el('a', { href: `/runs/${j.id}` }, `#${j.id}`) : `#${j.id}`),
      el('td', {}, j.kind), el('td', {}, badge(j.state)), el('td', {}, j.algorithm),
      el('td', {}, j.kind === 'train' ? (j.spec.seed ?? 0) : ''),
      el('td', {}, j.result && j.result.success_rate !== undefined ? `success ${fmtNum(j.result.success_rate)}` : (j.error || ''))))));
}
