// First-person "fly" navigation for the 3D view: W/S or ↑/↓ move along the view direction, A/D or ←/→ sideways,
// E/Q (or PageUp/PageDown) up and down along the model's up axis; dragging with the mouse turns the view (yaw about
// the up axis, pitch kept short of the vertical); the wheel changes the speed; Shift moves four times faster.
import * as THREE from 'three';

const KEYS: Record<string, [number, number, number]> = {
  KeyW: [0, 0, 1], ArrowUp: [0, 0, 1], KeyS: [0, 0, -1], ArrowDown: [0, 0, -1],
  KeyD: [1, 0, 0], ArrowRight: [1, 0, 0], KeyA: [-1, 0, 0], ArrowLeft: [-1, 0, 0],
  KeyE: [0, 1, 0], PageUp: [0, 1, 0], KeyQ: [0, -1, 0], PageDown: [0, -1, 0],
};

export class FlyControls {
  enabled = false;
  /** Model units per second. */
  speed = 1;
  /** Radians per pixel of mouse drag. */
  lookSpeed = 0.004;
  private held = new Set<string>();
  private fast = false;
  private drag: { x: number; y: number } | null = null;
  private last = 0;

  constructor(private camera: THREE.PerspectiveCamera, private dom: HTMLElement, private up: () => THREE.Vector3,
              private changed: () => void) {
    dom.tabIndex = dom.tabIndex >= 0 ? dom.tabIndex : 0;
    dom.addEventListener('keydown', this.onKeyDown);
    dom.addEventListener('keyup', this.onKeyUp);
    dom.addEventListener('blur', this.onBlur);
    dom.addEventListener('pointerdown', this.onPointerDown);
    dom.addEventListener('pointermove', this.onPointerMove);
    dom.addEventListener('pointerup', this.onPointerUp);
    dom.addEventListener('wheel', this.onWheel, { passive: false });
  }

  /** Whether a movement key is held (the view must keep rendering). */
  moving(): boolean { return this.enabled && this.held.size > 0; }

  /** Advances the camera by the keys held since the last call. */
  update(now = performance.now()): void {
    const dt = this.last ? Math.min((now - this.last) / 1000, 0.1) : 0;
    this.last = now;
    if (!this.enabled || this.held.size === 0 || dt === 0) return;
    const up = this.up().clone().normalize();
    const forward = this.camera.getWorldDirection(new THREE.Vector3());
    const right = new THREE.Vector3().crossVectors(forward, up).normalize();
    const move = new THREE.Vector3();
    for (const k of this.held) {
      const [x, y, z] = KEYS[k];
      move.addScaledVector(right, x).addScaledVector(up, y).addScaledVector(forward, z);
    }
    if (move.lengthSq() === 0) return;
    move.normalize().multiplyScalar(this.speed * (this.fast ? 4 : 1) * dt);
    this.camera.position.add(move);
    this.camera.updateMatrixWorld();
    this.changed();
  }

  /** Turns the view: yaw about the model's up axis, pitch about the camera's right axis (never past vertical). */
  look(dx: number, dy: number): void {
    const up = this.up().clone().normalize();
    const forward = this.camera.getWorldDirection(new THREE.Vector3());
    const yaw = new THREE.Quaternion().setFromAxisAngle(up, -dx * this.lookSpeed);
    forward.applyQuaternion(yaw);
    const right = new THREE.Vector3().crossVectors(forward, up).normalize();
    const pitched = forward.clone().applyAxisAngle(right, -dy * this.lookSpeed);
    if (Math.abs(pitched.dot(up)) < 0.995) forward.copy(pitched);
    this.camera.up.copy(up);
    this.camera.lookAt(this.camera.position.clone().add(forward));
    this.camera.updateMatrixWorld();
    this.changed();
  }

  private onKeyDown = (e: KeyboardEvent): void => {
    if (!this.enabled || !(e.code in KEYS)) return;
    e.preventDefault();
    this.fast = e.shiftKey;
    if (this.held.size === 0) this.last = performance.now();
    this.held.add(e.code);
    this.changed();
  };
  private onKeyUp = (e: KeyboardEvent): void => { this.held.delete(e.code); this.fast = e.shiftKey; };
  private onBlur = (): void => { this.held.clear(); };
  private onPointerDown = (e: PointerEvent): void => {
    if (!this.enabled || e.button !== 0) return;
    this.dom.focus();
    this.drag = { x: e.clientX, y: e.clientY };
  };
  private onPointerMove = (e: PointerEvent): void => {
    if (!this.enabled || !this.drag) return;
    this.look(e.clientX - this.drag.x, e.clientY - this.drag.y);
    this.drag = { x: e.clientX, y: e.clientY };
  };
  private onPointerUp = (): void => { this.drag = null; };
  private onWheel = (e: WheelEvent): void => {
    if (!this.enabled) return;
    e.preventDefault();
    this.speed *= e.deltaY > 0 ? 1 / 1.25 : 1.25;
  };

  dispose(): void {
    this.dom.removeEventListener('keydown', this.onKeyDown);
    this.dom.removeEventListener('keyup', this.onKeyUp);
    this.dom.removeEventListener('blur', this.onBlur);
    this.dom.removeEventListener('pointerdown', this.onPointerDown);
    this.dom.removeEventListener('pointermove', this.onPointerMove);
    this.dom.removeEventListener('pointerup', this.onPointerUp);
    this.dom.removeEventListener('wheel', this.onWheel);
  }
}
