// Bus: what is on the wire, as CANalyzer's statistics and trace windows, cabana and
// SavvyCAN show it. Messages: one row per catalogue message (sender, DLC, count, period
// and jitter over the last 64 frames, overdue when silent for three cycles, last data with
// the bytes that changed, the decoded signals), sortable, filterable, with statistics that
// can be reset. Trace: every frame as it came (time, ID, name, sender, DLC, data), filtered
// and paused at will. The bus load is measured by the gateway from the frames' exact
// lengths on the wire; the DBC the bus is decoded with downloads from here.
import { get } from '../api';
import type { Ctx, View } from '../view';
import { h, num, setText } from '../util';

/** Rows the trace keeps. */
const TRACE_ROWS = 500;
/** How often the trace asks for new frames, ms. */
const TRACE_POLL_MS = 250;

type SortKey = 'id' | 'name' | 'sender' | 'count' | 'period';

interface Row {
  name: string;
  id: number;
  tr: HTMLElement;
  cells: Record<string, HTMLElement>;
  data: HTMLElement;
  last: string;
  text: string;
}

/** A trace frame as /api/trace sends it. */
type TraceFrame = [number, number, number, string, number, string, string, string];

function hexId(id: number, extended = false): string {
  return `0x${id.toString(16).toUpperCase().padStart(extended ? 8 : 3, '0')}`;
}

export function busView(ctx: Ctx): View {
  const { live } = ctx;
  const load = h('div', { class: 'figure', 'data-testid': 'bus-load' });
  const frames = h('div', { class: 'figure', 'data-testid': 'bus-frames' });
  const errors = h('div', { class: 'figure', 'data-testid': 'error-frames' });
  const unknown = h('div', { class: 'figure', 'data-testid': 'unknown-frames' });
  const diag = h('div', { class: 'figure' });
  const fd = h('div', { class: 'figure', 'data-testid': 'fd-frames' });
  const overdue = h('div', { class: 'figure', 'data-testid': 'overdue' });
  const since = h('div', { class: 'muted small', 'data-testid': 'stats-since' });
  const filter = h('input', { type: 'search', class: 'filter', placeholder: 'filter: ID, name, sender, signal', 'aria-label': 'filter the bus', 'data-testid': 'bus-filter' });
  const pause = h('button', { class: 'btn', 'data-testid': 'bus-pause' }, 'Pause');
  const reset = h('button', { class: 'btn', 'data-testid': 'bus-reset', title: 'counts from now on' }, 'Reset statistics');
  const dbc = h('a', { class: 'btn', href: '/api/dbc', download: 'autoplug.dbc', 'data-testid': 'dbc-download', title: 'the DBC file this bus is decoded with' }, 'Download DBC');
  const tabMessages = h('button', { class: 'btn active', 'data-testid': 'tab-messages' }, 'Messages');
  const tabTrace = h('button', { class: 'btn', 'data-testid': 'tab-trace' }, 'Trace');
  const body = h('tbody');
  const head = h('tr');
  const table = h('div', { class: 'card table-wrap', 'data-testid': 'bus-messages' }, h('table', { class: 'grid' }, h('thead', {}, head), body));
  const traceBody = h('tbody');
  const traceNote = h('div', { class: 'muted small', 'data-testid': 'trace-note' });
  const trace = h('div', { class: 'card table-wrap trace', 'data-testid': 'bus-trace', hidden: true },
    traceNote,
    h('table', { class: 'grid mono-table' },
      h('thead', {}, h('tr', {}, ...['Time (s)', 'ID', 'Name', 'Sender', 'DLC', 'Data'].map((t) => h('th', { text: t })))),
      traceBody));
  const el = h('section', { class: 'bus' },
    h('div', { class: 'card stats' },
      h('div', {}, h('div', { class: 'muted small', text: 'Bus load (500 kbit/s)' }), load),
      h('div', {}, h('div', { class: 'muted small', text: 'Frames' }), frames),
      h('div', {}, h('div', { class: 'muted small', text: 'Error frames' }), errors),
      h('div', {}, h('div', { class: 'muted small', text: 'Unknown IDs (frames)' }), unknown),
      h('div', {}, h('div', { class: 'muted small', text: 'Diagnostic frames' }), diag),
      h('div', { title: 'CAN FD frames (from a log of another bus): counted, not decoded; a classic bus cannot carry them' },
        h('div', { class: 'muted small', text: 'CAN FD frames' }), fd),
      h('div', {}, h('div', { class: 'muted small', text: 'Overdue messages' }), overdue),
      since),
    h('div', { class: 'toolbar' }, h('span', { class: 'btn-group' }, tabMessages, tabTrace), filter, pause, reset, dbc),
    table, trace);

  let paused = false;
  let mode: 'messages' | 'trace' = 'messages';
  pause.addEventListener('click', () => {
    paused = !paused;
    pause.classList.toggle('active', paused);
    setText(pause, paused ? 'Resume' : 'Pause');
    el.dataset.paused = String(paused);
  });
  const showTab = (m: typeof mode) => {
    mode = m;
    tabMessages.classList.toggle('active', m === 'messages');
    tabTrace.classList.toggle('active', m === 'trace');
    table.hidden = m !== 'messages';
    trace.hidden = m !== 'trace';
    if (m === 'trace') void poll();
  };
  tabMessages.addEventListener('click', () => showTab('messages'));
  tabTrace.addEventListener('click', () => showTab('trace'));
  filter.addEventListener('input', () => {
    applyFilter();
    for (const tr of traceBody.children) (tr as HTMLElement).hidden = !matches((tr as HTMLElement).dataset.text ?? '');
  });

  // ---- statistics, since the page opened or the last reset ----
  let base = { t: 0, counts: new Map<string, number>(), frames: 0, errors: 0, unknown: 0, diag: 0, fd: 0 };
  function resetStats(): void {
    const b = live.bus;
    base = {
      t: live.t,
      counts: new Map([...live.messages].map(([name, m]) => [name, m.count])),
      frames: b?.frames ?? 0,
      errors: b?.error_frames ?? 0,
      unknown: b?.unknown_frames ?? 0,
      diag: b?.diagnostic_frames ?? 0,
      fd: b?.fd_frames ?? 0,
    };
  }
  let resetDone = false;
  reset.addEventListener('click', () => {
    resetStats();
    resetDone = true;
    render(true);
  });

  // ---- the messages table ----
  const columns: [string, string, SortKey | null][] = [
    ['id', 'ID', 'id'], ['name', 'Message', 'name'], ['sender', 'Sender', 'sender'], ['dlc', 'DLC', null],
    ['count', 'Count', 'count'], ['period', 'Period', 'period'], ['jitter', 'Jitter', null], ['state', 'State', null],
  ];
  let sortKey: SortKey = 'id';
  let sortDown = false;
  for (const [, label, key] of columns) {
    const th = h('th', { text: label });
    if (key) {
      th.classList.add('sortable');
      th.title = 'sort';
      th.addEventListener('click', () => {
        sortDown = sortKey === key ? !sortDown : false;
        sortKey = key;
        sortRows();
      });
    }
    head.append(th);
  }
  head.append(h('th', { text: 'Data' }), h('th', { text: 'Signals' }));
  const rows = new Map<string, Row>();

  function build(): void {
    for (const m of live.messageSpecs) {
      const cells: Record<string, HTMLElement> = {};
      for (const [key] of columns) cells[key] = h('td');
      const data = h('td', { class: 'mono' });
      const signals = h('td', { class: 'small' });
      cells.signals = signals;
      const tr = h('tr', { 'data-testid': `msg-${m.name}` }, ...columns.map(([key]) => cells[key]), data, signals);
      setText(cells.id, hexId(m.id));
      setText(cells.name, m.name);
      setText(cells.sender, m.senders.join(' '));
      setText(cells.dlc, String(m.dlc));
      rows.set(m.name, { name: m.name, id: m.id, tr, cells, data, last: '', text: '' });
    }
    sortRows();
  }

  function sortRows(): void {
    const spec = new Map(live.messageSpecs.map((m) => [m.name, m]));
    const value = (r: Row): number | string => {
      const m = live.messages.get(r.name);
      switch (sortKey) {
        case 'id': return r.id;
        case 'name': return r.name;
        case 'sender': return spec.get(r.name)?.senders.join(' ') ?? '';
        case 'count': return (m?.count ?? 0) - (base.counts.get(r.name) ?? 0);
        case 'period': return m?.period_ms ?? Infinity;
      }
    };
    const sorted = [...rows.values()].sort((a, b) => {
      const x = value(a), y = value(b);
      const order = x < y ? -1 : x > y ? 1 : 0;
      return sortDown ? -order : order;
    });
    body.replaceChildren(...sorted.map((r) => r.tr));
    for (const th of head.children) th.classList.remove('sorted-up', 'sorted-down');
    const index = columns.findIndex(([, , key]) => key === sortKey);
    head.children[index]?.classList.add(sortDown ? 'sorted-down' : 'sorted-up');
  }

  function matches(text: string): boolean {
    const words = filter.value.toLowerCase().split(/\s+/).filter(Boolean);
    return words.every((w) => text.includes(w));
  }

  function applyFilter(): void {
    for (const r of rows.values()) r.tr.hidden = !matches(r.text);
  }

  let lastRender = 0;
  function render(force = false): void {
    const now = performance.now();
    if (!force && (paused || now - lastRender < 200)) return;
    lastRender = now;
    if (rows.size === 0 && live.messageSpecs.length) build();
    const spec = new Map(live.messageSpecs.map((m) => [m.name, m]));
    let late = 0;
    for (const [name, row] of rows) {
      const m = live.messages.get(name);
      const info = spec.get(name);
      if (!m || !info) continue;
      const count = m.count - (base.counts.get(name) ?? 0);
      setText(row.cells.count, String(count));
      // Overdue: nothing for three cycles, as the gateway judges a signal stale.
      const silent = m.last_t === null || m.last_t === undefined ? null : live.t - m.last_t;
      const isLate = m.count > 0 && silent !== null && silent * 1000 > 3 * info.cycle_ms;
      if (isLate) late++;
      row.tr.classList.toggle('overdue', isLate);
      setText(row.cells.period, isLate || m.period_ms === null ? '–' : `${num(m.period_ms, 1)} ms`);
      setText(row.cells.jitter, isLate || m.jitter_ms === null ? '–' : `${num(m.jitter_ms, 2)} ms`);
      setText(row.cells.state, m.count === 0 ? 'not seen' : isLate ? `overdue (silent ${num(silent, 1)} s)` : 'ok');
      row.cells.state.className = isLate || m.count === 0 ? 'bad' : 'ok';
      if (m.data !== row.last) {
        row.data.replaceChildren();
        for (let i = 0; i < m.data.length; i += 2) {
          const byte = m.data.slice(i, i + 2);
          const changed = row.last && row.last.slice(i, i + 2) !== byte;
          row.data.append(h('span', { class: changed ? 'byte changed' : 'byte', text: byte }));
        }
        row.last = m.data;
      }
      const decoded = live.catalog
        .filter((s) => s.name.startsWith(`${name}.`))
        .map((s) => {
          const label = live.label(s.path);
          const v = live.value(s.path);
          const figure = v !== null && Number.isInteger(v) ? String(v) : num(v, Math.abs(v ?? 0) < 10 ? 2 : 0);
          return `${s.name.slice(name.length + 1)} ${label ?? figure}${label ? '' : s.unit ? ` ${s.unit}` : ''}`;
        })
        .join(' · ');
      setText(row.cells.signals, decoded);
      row.text = `${hexId(row.id).toLowerCase()} ${row.id} ${name} ${info.senders.join(' ')} ${decoded}`.toLowerCase();
    }
    applyFilter();
    if (sortKey === 'count' || sortKey === 'period') sortRows();
    const b = live.bus;
    if (b) {
      setText(load, b.load_percent === null || b.load_percent === undefined ? '–' : `${num(b.load_percent, 1)} %`);
      setText(frames, String(b.frames - base.frames));
      setText(errors, String(b.error_frames - base.errors));
      errors.classList.toggle('bad', b.error_frames > base.errors);
      setText(unknown, String(b.unknown_frames - base.unknown));
      setText(diag, String(b.diagnostic_frames - base.diag));
      setText(fd, String(b.fd_frames - base.fd));
    }
    setText(overdue, String(late));
    overdue.classList.toggle('bad', late > 0);
    setText(since, resetDone ? `counts since t = ${num(base.t, 1)} s` : 'counts since the session began');
  }

  // ---- the trace ----
  let lastSeq = 0;
  let polling = false;
  let timer = 0;
  async function poll(): Promise<void> {
    if (polling || mode !== 'trace' || paused) return;
    polling = true;
    try {
      const page = await get(`/api/trace?after=${lastSeq}&limit=${TRACE_ROWS}`);
      if (page.last < lastSeq) {
        // The gateway started again: its numbers start over.
        traceBody.replaceChildren();
      }
      lastSeq = page.last;
      const added: HTMLElement[] = [];
      for (const f of page.frames as TraceFrame[]) added.push(traceRow(f));
      traceBody.prepend(...added.reverse());
      while (traceBody.childElementCount > TRACE_ROWS) traceBody.lastElementChild!.remove();
      setText(traceNote, page.missed > 0
        ? `newest first; ${page.missed} frames came faster than the page could take them and are not shown`
        : `newest first; the last ${TRACE_ROWS} frames are kept`);
      trace.dataset.last = String(lastSeq);
    } catch (e: any) {
      setText(traceNote, `trace unavailable: ${e.message ?? e}`);
    } finally {
      polling = false;
    }
  }
  function traceRow(f: TraceFrame): HTMLElement {
    const [seq, t, id, flags, dlc, data, name, sender] = f;
    const extended = flags.includes('x');
    const kind = flags.includes('e') ? 'error frame'
      : flags.includes('r') ? 'remote'
      : flags.includes('f') ? 'CAN FD' : '';
    const bytes = data.match(/../g)?.join(' ') ?? '';
    const tr = h('tr', { 'data-seq': String(seq), class: flags.includes('e') ? 'bad' : '' },
      h('td', { text: t.toFixed(6) }),
      h('td', { text: flags.includes('e') ? '–' : hexId(id, extended) }),
      h('td', { text: name || kind || 'unknown' }),
      h('td', { text: sender }),
      h('td', { text: String(dlc) }),
      h('td', { text: bytes }));
    tr.dataset.text = `${hexId(id, extended).toLowerCase()} ${id} ${name} ${sender} ${kind} ${bytes}`.toLowerCase();
    tr.hidden = !matches(tr.dataset.text);
    return tr;
  }
  timer = window.setInterval(() => void poll(), TRACE_POLL_MS);

  return {
    el,
    update: () => render(),
    destroy() {
      clearInterval(timer);
    },
  };
}
