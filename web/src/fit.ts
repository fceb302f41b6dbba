// "Fit view": a camera pose that frames a point set over most of the canvas, from robust (percentile) bounds in an
// up-aligned frame whose first axis is the set's long horizontal axis, so a long flight strip lies across the screen.
import * as THREE from 'three';

export interface Frame { center: THREE.Vector3; axes: [THREE.Vector3, THREE.Vector3, THREE.Vector3]; half: THREE.Vector3; }

function percentile(sorted: Float64Array, q: number): number {
  if (sorted.length === 0) return 0;
  const i = Math.min(sorted.length - 1, Math.max(0, Math.round(q * (sorted.length - 1))));
  return sorted[i];
}

/** Oriented robust bounds of `xyz` (2nd–98th percentile per axis), with axes[2] = up. */
export function robustFrame(xyz: ArrayLike<number>, up: THREE.Vector3): Frame | null {
  const n = Math.floor(xyz.length / 3);
  if (n === 0) return null;
  const u = up.clone().normalize();
  const tmp = Math.abs(u.x) < 0.9 ? new THREE.Vector3(1, 0, 0) : new THREE.Vector3(0, 1, 0);
  const e1 = tmp.sub(u.clone().multiplyScalar(tmp.dot(u))).normalize();
  const e2 = new THREE.Vector3().crossVectors(u, e1);
  // Horizontal principal axis.
  let mx = 0, my = 0;
  const a = new Float64Array(n), b = new Float64Array(n);
  for (let i = 0; i < n; i++) {
    const x = xyz[3 * i], y = xyz[3 * i + 1], z = xyz[3 * i + 2];
    a[i] = x * e1.x + y * e1.y + z * e1.z; b[i] = x * e2.x + y * e2.y + z * e2.z; mx += a[i]; my += b[i];
  }
  mx /= n; my /= n;
  let sxx = 0, sxy = 0, syy = 0;
  for (let i = 0; i < n; i++) { const dx = a[i] - mx, dy = b[i] - my; sxx += dx * dx; sxy += dx * dy; syy += dy * dy; }
  const theta = 0.5 * Math.atan2(2 * sxy, sxx - syy);
  const ax = e1.clone().multiplyScalar(Math.cos(theta)).addScaledVector(e2, Math.sin(theta));
  const ay = new THREE.Vector3().crossVectors(u, ax);
  const axes: [THREE.Vector3, THREE.Vector3, THREE.Vector3] = [ax, ay, u];
  const lo = new THREE.Vector3(), hi = new THREE.Vector3();
  for (let k = 0; k < 3; k++) {
    const v = new Float64Array(n);
    const d = axes[k];
    for (let i = 0; i < n; i++) v[i] = xyz[3 * i] * d.x + xyz[3 * i + 1] * d.y + xyz[3 * i + 2] * d.z;
    v.sort();
    lo.setComponent(k, percentile(v, 0.02));
    hi.setComponent(k, percentile(v, 0.98));
  }
  const mid = lo.clone().add(hi).multiplyScalar(0.5);
  const center = new THREE.Vector3().addScaledVector(ax, mid.x).addScaledVector(ay, mid.y).addScaledVector(u, mid.z);
  const half = hi.clone().sub(lo).multiplyScalar(0.5);
  const floor = Math.max(half.x, half.y, half.z) * 1e-3 + 1e-9;
  half.set(Math.max(half.x, floor), Math.max(half.y, floor), Math.max(half.z, floor));
  return { center, axes, half };
}

/**
 * Places `camera` looking at the frame's centre from `elevationDeg` above its horizontal plane, on the side of its
 * short axis, at the smallest distance at which every corner of the box lies within `fill` of the viewport.
 */
export function fitCamera(camera: THREE.PerspectiveCamera, f: Frame, elevationDeg = 60, fill = 0.94): THREE.Vector3 {
  const el = THREE.MathUtils.degToRad(elevationDeg);
  const [ax, ay, up] = f.axes;
  const back = up.clone().multiplyScalar(Math.sin(el)).addScaledVector(ay, -Math.cos(el)).normalize(); // from target to eye
  const right = ax.clone();
  const camUp = new THREE.Vector3().crossVectors(back, right).normalize().negate();
  if (camUp.dot(up) < 0) camUp.negate();
  const tanV = Math.tan(THREE.MathUtils.degToRad(camera.fov) / 2) * fill;
  const tanH = tanV * camera.aspect;
  let d = 0;
  for (let i = 0; i < 8; i++) {
    const c = new THREE.Vector3()
      .addScaledVector(ax, (i & 1 ? 1 : -1) * f.half.x)
      .addScaledVector(ay, (i & 2 ? 1 : -1) * f.half.y)
      .addScaledVector(up, (i & 4 ? 1 : -1) * f.half.z);
    const along = c.dot(back); // the corner's offset towards the eye
    const x = Math.abs(c.dot(right)), y = Math.abs(c.dot(camUp));
    d = Math.max(d, along + x / tanH, along + y / tanV);
  }
  camera.up.copy(up);
  camera.position.copy(f.center).addScaledVector(back, d);
  camera.near = Math.max(d * 1e-3, 1e-4);
  camera.far = d * 50;
  camera.lookAt(f.center);
  camera.updateProjectionMatrix();
  return f.center.clone();
}
