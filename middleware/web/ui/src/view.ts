import type { DriveInput } from './drive-input';
import type { Live } from './live';

export interface Ctx {
  live: Live;
  /** The person's controls of the virtual car (one per page; absent on a fleet page). */
  drive?: DriveInput;
  /** A short message at the bottom of the page. */
  toast(text: string, kind?: 'ok' | 'error'): void;
}

export interface View {
  el: HTMLElement;
  /** Called when the live data changed (at most once per animation frame). */
  update(): void;
  destroy?(): void;
}
