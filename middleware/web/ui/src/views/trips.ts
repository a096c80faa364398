// Trips: the trip under way, and the stored ones with their statistics and plots.
import uPlot from 'uplot';
import 'uplot/dist/uPlot.min.css';
import { get } from '../api';
import type { Ctx, View } from '../view';
import { h, num, seconds, utc } from '../util';

function stats(s: Record<string, number>): HTMLElement {
  const items: [string, string][] = [
    ['Duration', seconds(s.duration_s)],
    ['Distance', `${num(s.distance_m / 1000, 2)} km`],
    ['Fuel', `${num(s.fuel_used_l, 2)} L`],
    ['Max speed', `${num(s.max_speed_kmh)} km/h`],
    ['Mean speed', `${num(s.mean_speed_kmh, 1)} km/h`],
    ['Shifts', String(s.shifts)],
    ['ABS', `${s.abs_interventions} × (${num(s.abs_time_s, 1)} s)`],
    ['Hard brakings', String(s.hard_brakings)],
    ['Cruise', seconds(s.cruise_time_s)],
    ['Differential', `${s.diff_interventions} × (${num(s.diff_time_s, 1)} s)`],
  ];
  return h('dl', { class: 'stats-grid' }, ...items.flatMap(([k, v]) => [h('dt', { text: k }), h('dd', { text: v })]));
}

/** Verdicts as a list: the ECU, its verdict, the number and the evidence. */
function verdictList(verdicts: { ecu: string; verdict: string; number: number | null; unit: string | null; evidence: string | null }[], testid: string): HTMLElement {
  if (verdicts.length === 0) return h('p', { class: 'muted', 'data-testid': testid, text: 'No verdicts.' });
  return h('ul', { class: 'verdict-list', 'data-testid': testid }, ...verdicts.map((v) =>
    h('li', { 'data-ecu': v.ecu },
      h('strong', { text: `${v.ecu} ` }),
      h('span', { class: `verdict v-${v.verdict.replace(/ /g, '-')}`, text: v.verdict }),
      v.number === null ? '' : ` ${num(v.number, 3)} ${v.unit ?? ''}`,
      v.evidence ? h('span', { class: 'muted', text: ` — ${v.evidence}` }) : '')));
}

/** Trouble codes as a list: the ECU, the code, what it means. */
function codeList(codes: { ecu: string; code: string; description: string }[], testid: string): HTMLElement {
  if (codes.length === 0) return h('p', { class: 'muted', 'data-testid': testid, text: 'No trouble codes.' });
  return h('ul', { 'data-testid': testid }, ...codes.map((c) => h('li', {}, h('strong', { text: `${c.ecu} ${c.code}` }), ` ${c.description}`)));
}

export function tripsView(ctx: Ctx): View {
  const { live } = ctx;
  const current = h('div', { 'data-testid': 'trip-current' });
  const list = h('tbody');
  const detail = h('div', { class: 'card', hidden: true });
  let plot: uPlot | null = null;
  const el = h('section', { class: 'trips' },
    h('div', { class: 'card' }, h('h3', { text: 'Trip under way' }), current),
    h('div', { class: 'card table-wrap' }, h('h3', { text: 'Stored trips' }),
      h('table', { class: 'grid' }, h('thead', {}, h('tr', {}, ...['#', 'Started', 'Vehicle', 'Status', 'Duration', 'km', 'Max km/h'].map((t) => h('th', { text: t })))), list)),
    detail,
  );

  async function load(): Promise<void> {
    try {
      const rows: any[] = await get('/api/trips');
      list.replaceChildren(...rows.map((r) => {
        const tr = h('tr', { class: 'clickable', tabindex: 0 },
          h('td', { text: String(r.id) }), h('td', { text: utc(r.started_at_unix_ms) }), h('td', { text: r.vehicle }),
          h('td', { text: r.status }), h('td', { text: seconds(r.stats.duration_s) }),
          h('td', { text: num(r.stats.distance_m / 1000, 2) }), h('td', { text: num(r.stats.max_speed_kmh) }));
        tr.addEventListener('click', () => void show(r.id));
        return tr;
      }));
      if (rows.length === 0) list.append(h('tr', {}, h('td', { colspan: 7, class: 'muted', text: 'No trip stored yet: drive the car.' })));
    } catch (e: any) {
      list.replaceChildren(h('tr', {}, h('td', { colspan: 7, class: 'muted', text: e.message })));
    }
  }

  async function show(id: number): Promise<void> {
    try {
      const d = await get(`/api/trips/${id}`);
      const signal = d.series_signals.includes('Vehicle.Speed') ? 'Vehicle.Speed' : d.series_signals[0];
      const chart = h('div', { class: 'chart' });
      detail.hidden = false;
      // A trip keeps its verdicts and codes when it ends; one under way shows the
      // gateway's as they stand, and says so.
      const open = d.row.status === 'open';
      const s = live.session;
      const verdicts = open ? (s?.diagnostics ?? []) : d.verdicts;
      const codes = open
        ? (s?.dtcs ?? []).flatMap((r) => r.codes.map((c) => ({ ecu: r.ecu, code: c.code, description: c.description })))
        : d.dtcs;
      detail.hidden = false;
      detail.replaceChildren(h('h3', { text: `Trip ${id}` }), stats(d.row.stats),
        h('h4', { text: open ? 'Verdicts so far (kept when the trip ends)' : d.row.status === 'interrupted' ? 'Verdicts (none kept: the gateway stopped during the trip)' : 'Verdicts at the end of the trip' }),
        verdictList(verdicts, 'trip-verdicts'),
        h('h4', { text: open ? 'Trouble codes so far' : 'Trouble codes at the end of the trip' }),
        codeList(codes, 'trip-dtcs'),
        chart);
      plot?.destroy();
      plot = null;
      if (signal) {
        const points: any[] = await get(`/api/trips/${id}/series?signal=${encodeURIComponent(signal)}`);
        plot = new uPlot({
          title: `${signal}, 1 s buckets (mean, min, max)`,
          width: Math.max(280, detail.clientWidth - 24), height: 220,
          scales: { x: { time: false } },
          axes: [{ label: 'bus time (s)', stroke: 'currentColor' }, { stroke: 'currentColor' }],
          series: [{}, { label: 'mean', stroke: 'hsl(205 75% 50%)' }, { label: 'min', stroke: 'hsl(205 40% 70%)' }, { label: 'max', stroke: 'hsl(25 75% 55%)' }],
        }, [points.map((p) => p.t_s), points.map((p) => p.mean), points.map((p) => p.min), points.map((p) => p.max)], chart);
      }
    } catch (e: any) {
      ctx.toast(e.message, 'error');
    }
  }

  let lastTrip = '';
  function update(): void {
    const s = live.session;
    const t = s?.trip ?? null;
    const text = JSON.stringify([t, s?.diagnostics.map((d) => d.verdict), s?.dtcs]);
    if (text === lastTrip) return;
    const wasOpen = lastTrip !== '' && !lastTrip.startsWith('[null');
    lastTrip = text;
    const codes = (s?.dtcs ?? []).flatMap((r) => r.codes.map((c) => ({ ecu: r.ecu, code: c.code, description: c.description })));
    current.replaceChildren(...(t
      ? [stats(t), h('h4', { text: 'Verdicts so far' }), verdictList(s?.diagnostics ?? [], 'current-verdicts'), h('h4', { text: 'Trouble codes so far' }), codeList(codes, 'current-dtcs')]
      : [h('p', { class: 'muted', text: 'No trip under way (the engine is off and the car stands).' })]));
    if (wasOpen && !t) void load();
  }
  void load();
  return { el, update, destroy: () => plot?.destroy() };
}
