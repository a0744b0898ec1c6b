// A run: live training curves with smoothing and x-axis controls, its checkpoints (download,
// evaluate, how made), its evaluations with their videos and its recent episodes.
import {
  ApiError, asObject, badge, chartControls, chartSettings, drawChart, duration, el, errorBox, fmtNum,
  fmtBytes, fmtTime, getJson, notFound, onChange, phaseOf, phaseText, send, tasksOf,
} from './api.js';
import { lineageButton } from './lineage.js';

const METRICS = ['success', 'task_success', 'episode_length', 'return', 'reward_split', 'stages', 'entropy', 'value_loss', 'learning_rate'];

export async function renderRun(main, idText) {
  const id = Number(idText);
  if (!Number.isInteger(id) || id < 1) return notFound(main, `"${idText}" is not a run id.`);
  let data;
  try {
    data = await getJson(`/api/v1/runs/${id}`);
  } catch (err) {
    if (err instanceof ApiError && err.status === 404) return notFound(main, `Run ${id} does not exist (${err.message}).`);
    return main.replaceChildren(errorBox(err));
  }
  document.title = `Run ${id} · crm-grasp`;
  const header = el('section', { class: 'run-header' });
  const figures = METRICS.map((metric) => el('figure', { class: 'chart', 'data-metric': metric }));
  const message = el('div', { class: 'message', role: 'status' });
  const checkpoints = el('tbody');
  const lineage = el('section', { id: 'lineage-view' });
  const evaluations = el('div');
  const episodes = el('div', { id: 'episodes-section' });
  const recording = el('div', { id: 'recording' });
  const deleteButton = el('button', { type: 'button', id: 'delete-run', class: 'danger', onclick: () => remove() }, 'Delete run');
  const episodesInput = el('input', { type: 'text', inputmode: 'numeric', value: '100', name: 'eval-episodes', size: 6 });
  // Evaluations sample the policy (the paper's way) unless the deterministic action is asked for.
  const meanInput = el('input', { type: 'checkbox', name: 'eval-deterministic' });
  // A GIF of the evaluation's first episodes, which the Videos section plays.
  const videoInput = el('input', { type: 'checkbox', name: 'eval-video' });
  const videos = el('div', { id: 'videos' });

  const drawCharts = () => {
    const { smooth, x } = chartSettings();
    figures.forEach((figure) => drawChart(figure, {
      runs: String(id), metric: figure.dataset.metric, smooth, x, width: 560, height: 300,
    }));
  };
  main.replaceChildren(
    header,
    el('div', { class: 'toolbar' }, chartControls(drawCharts), el('span', { class: 'spacer' }),
      el('a', { href: `/compare?runs=${id}`, class: 'button' }, 'Compare with other runs'), ' ', deleteButton),
    el('div', { class: 'charts' }, figures),
    message,
    el('h2', {}, 'Checkpoints'),
    el('p', { class: 'muted' }, 'Evaluate with ', episodesInput, ' episodes (',
      el('label', {}, meanInput, ' deterministic action instead of sampled'), '; ',
      el('label', {}, videoInput, ' with a video of the first 3 episodes'), '); the result appears under Evaluations.'),
    el('table', { id: 'checkpoints' }, el('thead', {}, el('tr', {},
      ['id', 'steps', 'size', 'saved', ''].map((h) => el('th', {}, h)))), checkpoints),
    lineage,
    el('h2', {}, 'Evaluations'), evaluations,
    el('h2', {}, 'Videos'), videos,
    el('h2', {}, 'Rerun recording'), recording,
    el('h2', {}, 'Episodes and their stage transitions'), episodes);

  // Deleting removes the run's checkpoints, recording, metrics and evaluations for good.
  async function remove() {
    if (!window.confirm(`Delete run #${id} with its checkpoints, recording, metrics and evaluations?`)) return;
    try {
      const done = await send('DELETE', `/api/v1/runs/${id}`);
      main.replaceChildren(el('div', { class: 'ok', id: 'deleted' },
        `Run #${done.deleted} deleted; ${fmtBytes(done.freed_bytes)} freed. `, el('a', { href: '/' }, 'Back to the jobs')));
    } catch (err) {
      message.replaceChildren(errorBox(err));
    }
  }

  const evaluate = (checkpoint) => queueEvaluation(checkpoint, episodesInput, meanInput, message, videoInput);

  function show(d) {
    const run = d.run;
    const spec = asObject(run.spec);
    const last = d.metrics.length ? asObject(d.metrics[d.metrics.length - 1].data) : null;
    const finished = !['queued', 'running'].includes(run.state);
    deleteButton.disabled = !finished;
    deleteButton.title = finished ? 'Delete this run and everything it stored' : 'Cancel the run before deleting it';
    header.replaceChildren(
      el('h1', {}, `Run #${run.id} `, el('small', {}, run.algorithm), ' ', badge(run.state)),
      el('dl', { class: 'facts' },
        ...fact('world', spec.world || 'crm'),
        ...fact('tasks', tasksOf(run)), ...fact('topology', spec.topology || 'task'), ...fact('seed', spec.seed ?? 0),
        ...(run.state === 'running' && phaseOf(run) ? fact('phase', el('span', { id: 'phase' }, phaseText(phaseOf(run)))) : []),
        ...fact('steps', `${run.steps.toLocaleString()} of ${(spec.steps || 0).toLocaleString()} (${Math.round(100 * run.progress)}%)`),
        ...fact('steps/s', run.steps_per_s ? Math.round(run.steps_per_s) : ''),
        ...fact('success (last 100)', last ? fmtNum(last.success_rate_last_100) : ''),
        ...fact('started', fmtTime(run.started_at)), ...fact('duration', duration(run)),
        ...fact('disk', fmtBytes(d.disk_bytes || 0)),
        ...fact('attempts', run.attempts), ...(run.rerun_of ? fact('re-run of', el('a', { href: `/runs/${run.rerun_of}` }, `#${run.rerun_of}`)) : []),
        ...(run.error ? fact('error', el('span', { class: 'bad' }, run.error)) : [])),
      el('details', {}, el('summary', {}, 'configuration'), el('pre', {}, JSON.stringify(spec, null, 2))));
    checkpoints.replaceChildren(...d.checkpoints.map((c) => el('tr', { 'data-checkpoint': c.id },
      el('td', {}, c.id), el('td', {}, c.steps.toLocaleString()), el('td', {}, `${Math.round(c.size / 1024)} KiB`),
      el('td', {}, fmtTime(c.created_at)),
      el('td', {}, el('a', { href: `/api/v1/checkpoints/${c.id}/download`, class: 'button small', download: true }, 'Download'), ' ',
        el('button', { type: 'button', class: 'small', onclick: () => evaluate(c) }, 'Evaluate'), ' ',
        lineageButton(c, lineage)))));
    if (!d.checkpoints.length) checkpoints.append(el('tr', {}, el('td', { colspan: 5, class: 'muted' }, 'No checkpoint yet.')));
    evaluations.replaceChildren(evaluationTable(d.evaluations));
    videos.replaceChildren(...videoList(d.videos || []));
    recording.replaceChildren(...recordingInfo(run, d.recording));
    showEpisodes(d);
  }

  // Training runs list the episodes they record; evaluations keep each episode's
  // transitions, and a run that records none shows its latest evaluation's.
  async function showEpisodes(d) {
    const finished = d.evaluations.find((e) => e.state === 'succeeded');
    if (d.episodes.length || !finished) {
      const none = d.run.kind === 'train' && !asObject(d.run.spec).record
        ? 'A training run lists the episodes it records: none here (set "record every N episodes" when submitting).'
        : 'No episode summaries yet.';
      episodes.replaceChildren(episodeList(d.episodes, none));
      return;
    }
    try {
      const evaluation = await getJson(`/api/v1/evaluations/${finished.id}`);
      episodes.replaceChildren(el('p', { class: 'muted' }, `From evaluation #${finished.id}.`), episodeList(evaluation.episodes));
    } catch (err) {
      episodes.replaceChildren(errorBox(err));
    }
  }

  show(data);
  drawCharts();
  onChange(async () => {
    try {
      const d = await getJson(`/api/v1/runs/${id}`);
      const moved = d.metrics.length !== data.metrics.length || d.run.state !== data.run.state;
      data = d;
      show(d);
      if (moved) drawCharts();
    } catch { /* the next change retries */ }
  });
}

// Each evaluation's video (a GIF, played by the browser as it loads), newest first.
function videoList(list) {
  if (!list.length) {
    return [el('p', { class: 'muted' }, 'No video yet: tick "with a video" before Evaluate (or ',
      el('code', {}, '"video": {"episodes": 3}'), ' in the API), or render one here: ',
      el('code', {}, 'crm record --checkpoint FILE --video episode.mp4'), '.')];
  }
  return list.slice().sort((a, b) => b.job_id - a.job_id).map((v) => el('figure', { class: 'video', 'data-job': v.job_id },
    el('img', { src: v.download, width: v.width, height: v.height, alt: `evaluation #${v.job_id}: its first ${v.episodes} episodes` }),
    el('figcaption', {}, `Evaluation #${v.job_id}: first ${v.episodes} episode${v.episodes === 1 ? '' : 's'}, `,
      `${v.frames} frames at 30 per second, ${fmtBytes(v.size)}. `,
      el('a', { href: v.download, download: `job${v.job_id}.gif` }, 'Download .gif'))));
}

function recordingInfo(run, rec) {
  if (!rec) {
    return [el('p', { class: 'muted' }, 'This run records nothing. Submit a job with "record every N episodes" set (or ',
      el('code', {}, '"record": {"every": 10}'), ' in the API), or replay a checkpoint: ',
      el('code', {}, 'crm record --checkpoint FILE --out episode.rrd'), '.')];
  }
  const url = new URL(rec.download, window.location.href).href;
  return [el('p', {},
    `${rec.episodes} episode${rec.episodes === 1 ? '' : 's'}, ${(rec.size / 1048576).toFixed(1)} MiB. `,
    el('a', { href: rec.download, class: 'button small', download: `job${run.id}.rrd` }, 'Download .rrd'),
    ' or open it in the viewer (', el('code', {}, 'pip install rerun-sdk==0.36.3'), '): ',
    el('code', { class: 'command' }, `rerun ${url}`))];
}

/** Queues an evaluation of `checkpoint` with the episodes, mean-action and video inputs' values;
 * says so (or shows the API's error) in `message`. */
export async function queueEvaluation(checkpoint, episodesInput, meanInput, message, videoInput) {
  const text = episodesInput.value.trim();
  const count = /^\d+$/.test(text) ? Number(text) : text;
  try {
    const body = { kind: 'eval', checkpoint_id: checkpoint.id, episodes: count };
    if (meanInput.checked) body.deterministic = true;
    if (videoInput && videoInput.checked) body.video = { episodes: 3 };
    const job = await send('POST', '/api/v1/jobs', body);
    message.replaceChildren(el('div', { class: 'ok' }, `Evaluation job ${job.id} queued for checkpoint ${checkpoint.id}.`));
  } catch (err) {
    message.replaceChildren(errorBox(err.field ? new Error(`${err.field}: ${err.message}`) : err));
  }
}

function fact(name, value) {
  return [el('dt', {}, name), el('dd', {}, value)];
}

/** The evaluations of checkpoints as Table I rows: overall and per-objective success. */
export function evaluationTable(evaluations) {
  if (!evaluations.length) return el('p', { class: 'muted' }, 'No evaluation yet: press Evaluate on a checkpoint.');
  const reports = evaluations.map((e) => (e.result && e.result.per_objective ? e.result : null));
  const objectives = [...new Set(reports.flatMap((r) => (r ? Object.keys(r.per_objective) : [])))].sort();
  return el('table', { id: 'evaluations' },
    el('thead', {}, el('tr', {}, ['id', 'checkpoint', 'state', 'tasks', 'topology', 'episodes', 'overall', ...objectives, 'outcomes', 'per task'].map((h) => el('th', {}, h)))),
    el('tbody', {}, evaluations.map((e, k) => {
      const r = reports[k];
      const spec = asObject(e.spec);
      return el('tr', {}, el('td', {}, e.id), el('td', {}, e.checkpoint_id), el('td', {}, badge(e.state)),
        el('td', { class: 'tasks' }, tasksOf(e)), el('td', {}, spec.topology || 'task'),
        el('td', {}, r ? r.episodes : ''), el('td', {}, r ? fmtNum(r.success_rate) : ''),
        objectives.map((o) => el('td', {}, r && r.per_objective[o] ? fmtNum(r.per_objective[o].success_rate) : '')),
        el('td', { class: 'outcomes' }, r && r.outcomes ? Object.entries(r.outcomes).map(([k, n]) => `${k} ${n}`).join(', ') : ''),
        el('td', {}, r ? perTask(r.per_task) : ''));
    })));
}

/** An evaluation's success per task, the weakest first, folded away. */
function perTask(perTaskRows) {
  const tasks = Object.entries(perTaskRows || {}).sort((a, b) => a[1].success_rate - b[1].success_rate || a[0].localeCompare(b[0]));
  if (!tasks.length) return '';
  return el('details', { class: 'per-task' },
    el('summary', {}, `${tasks.length} task${tasks.length === 1 ? '' : 's'}`),
    el('ul', {}, tasks.map(([task, row]) => el('li', { 'data-task': task }, `${task} ${fmtNum(row.success_rate)} (${row.episodes})${taskFailures(row.outcomes)}`))));
}

// A task's episodes that did not succeed, by cause (`: dropped 2, out_of_reach 1`); empty for
// reports made before 2026-11-24, which count endings only overall.
function taskFailures(outcomes) {
  const failed = Object.entries(outcomes || {})
    .filter(([outcome]) => outcome !== 'success')
    .map(([outcome, n]) => `${outcome.replace(/^failure \((.*)\)$/, '$1')} ${n}`);
  return failed.length ? `: ${failed.join(', ')}` : '';
}

function episodeList(episodes, none = 'No episode summaries yet.') {
  if (!episodes || !episodes.length) return el('p', { class: 'muted' }, none);
  const rows = episodes.slice(-20).reverse().map((e) => {
    const d = e || {};
    const history = (d.transitions || d.history || []).map((t) => `${t.from}→${t.to} (${t.event}, ${fmtNum(t.reward, 0)})`).join(', ');
    return el('tr', {}, el('td', {}, d.task || ''), el('td', {}, d.success === undefined ? '' : (d.success ? 'yes' : 'no')),
      el('td', {}, d.length ?? ''), el('td', {}, fmtNum(d.return, 1)), el('td', { class: 'history' }, history));
  });
  return el('table', { id: 'episodes' },
    el('thead', {}, el('tr', {}, ['task', 'success', 'length', 'return', 'stage transitions (event, reward)'].map((h) => el('th', {}, h)))),
    el('tbody', {}, rows));
}
