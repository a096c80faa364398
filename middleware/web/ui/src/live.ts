// The live stream (/api/stream): the catalogue, then updates with what changed. Keeps the
// latest value of every signal, each message's reception, the bus counters and the
// session's state, and tells the views when something changed. Reconnects on its own.

export interface SignalInfo {
  path: string;
  name: string;
  unit: string;
  cycle_ms: number;
  labels: [number, string][];
}

/** A catalogue message, as the catalogue describes it. */
export interface MessageSpec {
  name: string;
  id: number;
  dlc: number;
  cycle_ms: number;
  senders: string[];
}

export interface MessageInfo {
  id: number;
  count: number;
  wrong_length: number;
  invalid: number;
  period_ms: number | null;
  jitter_ms: number | null;
  /** Bus time of the latest frame, s. */
  last_t: number | null;
  data: string;
}

export interface BusFigures {
  frames: number;
  error_frames: number;
  unknown_frames: number;
  diagnostic_frames: number;
  /** CAN FD frames, counted apart: a classic bus leaves them aside. */
  fd_frames: number;
  /** The last second's bits on the wire, percent of the bit rate. */
  load_percent: number | null;
}

// The session's state, as the gateway writes it (see middleware/dashboard/src/session.rs).
export interface Session {
  source: { name: string; kind: string; transmit: boolean; drive: boolean; replay: boolean };
  tester: string | null;
  diagnostics: Diagnosis[];
  dtcs: { ecu: string; read_at: number; codes: { code: string; status: number; description: string }[] }[];
  inventory: {
    ecu: string;
    node: number | null;
    answered: boolean;
    part_number: string | null;
    software_version: string | null;
    hardware_version: string | null;
    serial_number: string | null;
    // F1A0: the slot the ECU runs (A, B) and that image's boot state.
    slot: string | null;
    boot_state: string | null;
  }[];
  flash: Flash | null;
  recording: { frames: number; bytes: number; file: string | null; failure: string | null } | null;
  driver: {
    person: boolean;
    held: DriveState | null;
    mu_left: number;
    mu_right: number;
    on_track: boolean;
    steers_along_road: boolean;
  } | null;
  trip: Record<string, number> | null;
  replay_page: { file: string; port: number; listening: boolean } | null;
  replay: { playing: boolean; speed: number; position_s: number; duration_s: number; at_end: boolean } | null;
  events: { t: number; text: string }[];
  fleet: FleetLink | null;
}

// The GDB servers on the virtual car's emulated ECUs (--gdb), as the gateway watches them
// (see middleware/dashboard/src/debuggers.rs). While one is halted the whole car stands still.
export interface Debuggers {
  ecus: { ecu: string; address: string; attached: boolean; halted: boolean; client: string | null }[];
}

// The vehicle's link to its fleet (the gateway started with --fleet).
export interface FleetLink {
  broker: string;
  online: boolean;
  connected: boolean;
  problem: string | null;
  vin: string | null;
  standing: boolean;
  offer: { campaign: number; name: string; ecu: string; version: string; message: string; bytes: number; question: string } | null;
  activity: { campaign: number; what: string } | null;
  reports: { campaign: number; state: string; reason: string | null; ecu: string; version_running: string | null; at_ms: number }[];
  events: string[];
  waiting_reports: number;
  dropped_reports: number;
}

export interface Diagnosis {
  ecu: string;
  node: number | null;
  verdict: string;
  routine: string | null;
  number: number | null;
  unit: string | null;
  suspect_above: number | null;
  faulty_above: number | null;
  evidence: string | null;
}

export interface Flash {
  ecu: string;
  image: string;
  version: string;
  variant: string;
  // The image that goes over CAN (a release's image for the slot the ECU writes).
  bytes: number;
  // The file as given: a release holds one image per slot.
  file_bytes: number;
  state: 'queued' | 'running' | 'done' | 'failed';
  phase: string | null;
  transferred: number | null;
  elapsed_s: number;
  report: { slot: string | null; image_bytes: number; total_s: number; phases: { phase: string; s: number }[]; throughput_bps: number | null } | null;
  error: string | null;
}

export interface DriveState {
  accelerator: number;
  brake: number;
  steering_deg: number;
  headlights: boolean;
  economy_mode: boolean;
  manual_mode: boolean;
  set_temp_f: number;
}

import { World } from './world';

type Listener = () => void;

export class Live {
  catalog: SignalInfo[] = [];
  byPath = new Map<string, SignalInfo>();
  messageSpecs: MessageSpec[] = [];
  values = new Map<string, number | null>();
  messages = new Map<string, MessageInfo>();
  bus: BusFigures | null = null;
  session: Session | null = null;
  debuggers: Debuggers | null = null;
  /** The simulator's world (the virtual car on its road), from the `world` messages. */
  world = new World();
  /** Bus time of the latest update, s. */
  t = 0;
  /** Wall time (performance.now) at which each signal last changed. */
  changedAt = new Map<string, number>();
  connected = false;
  private socket: WebSocket | null = null;
  private listeners = new Set<Listener>();
  private retry = 500;
  private onMessage = new Set<(m: any) => void>();

  connect(): void {
    const scheme = location.protocol === 'https:' ? 'wss' : 'ws';
    const socket = new WebSocket(`${scheme}://${location.host}/api/stream`);
    this.socket = socket;
    socket.onopen = () => {
      this.retry = 500;
    };
    socket.onmessage = (event) => {
      let message: any;
      try {
        message = JSON.parse(event.data);
      } catch {
        return;
      }
      this.take(message);
      for (const handler of this.onMessage) handler(message);
    };
    socket.onclose = () => {
      this.connected = false;
      this.socket = null;
      this.notify();
      setTimeout(() => this.connect(), this.retry);
      this.retry = Math.min(this.retry * 2, 5000);
    };
  }

  /** Sends a command on the stream (drive, press, auth); false when not connected. */
  send(command: object): boolean {
    if (!this.socket || this.socket.readyState !== WebSocket.OPEN) return false;
    this.socket.send(JSON.stringify(command));
    return true;
  }

  /** Calls `handler` with every message the gateway sends (after it was taken in). */
  listen(handler: (m: any) => void): () => void {
    this.onMessage.add(handler);
    return () => this.onMessage.delete(handler);
  }

  subscribe(listener: Listener): () => void {
    this.listeners.add(listener);
    return () => this.listeners.delete(listener);
  }

  private notify(): void {
    for (const listener of this.listeners) listener();
  }

  private take(message: any): void {
    if (message.type === 'catalog') {
      this.catalog = message.signals;
      this.byPath = new Map(this.catalog.map((s) => [s.path, s]));
      this.messageSpecs = message.messages ?? [];
      this.connected = true;
    } else if (message.type === 'update') {
      const now = performance.now();
      this.t = message.t;
      for (const [path, value] of Object.entries(message.signals as Record<string, number | null>)) {
        this.values.set(path, value);
        this.changedAt.set(path, now);
      }
      if (message.messages) {
        for (const [name, info] of Object.entries(message.messages as Record<string, MessageInfo>)) {
          this.messages.set(name, info);
        }
      }
      if (message.bus) this.bus = message.bus;
      if (message.session) this.session = message.session;
      if (message.debugger) this.debuggers = message.debugger;
      this.notify();
    } else if (message.type === 'world') {
      // Drawn at the display's rate by the world view: no notify.
      this.world.take(message);
    }
  }

  value(path: string): number | null {
    return this.values.get(path) ?? null;
  }

  /** The label of an enumeration's value, or null. */
  label(path: string): string | null {
    const v = this.value(path);
    const info = this.byPath.get(path);
    if (v === null || !info || info.labels.length === 0) return null;
    return info.labels.find(([raw]) => raw === v)?.[1] ?? String(v);
  }
}
