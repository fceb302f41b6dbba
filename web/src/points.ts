// The point material shared by the sparse cloud and the point tiles: colour / normal / number of views / height /
// confidence (the stated σ along the normal: green small, red at sigmaMax and above) modes chosen
// by a uniform, and points sized in world units (the tile's point spacing) so a dense cloud reads as a surface.
import * as THREE from 'three';

export enum PointMode { Color = 0, Normal = 1, Views = 2, Height = 3, Confidence = 4 }

export interface PointUniforms {
  mode: { value: number };
  projScale: { value: number };   // viewport height / (2 tan(fov/2)): world size → pixels at depth 1
  sizeScale: { value: number };   // user's multiplier on the spacing
  minPx: { value: number };
  viewsMax: { value: number };
  sigmaMax: { value: number };     // σ at the red end of the confidence ramp (a high percentile of the tiles' σ)
  heightRange: { value: THREE.Vector2 };
  up: { value: THREE.Vector3 };
}

export function createPointUniforms(): PointUniforms {
  return {
    mode: { value: PointMode.Color }, projScale: { value: 500 }, sizeScale: { value: 1.4 }, minPx: { value: 1.5 },
    viewsMax: { value: 2 }, sigmaMax: { value: 0 }, heightRange: { value: new THREE.Vector2(0, 1) }, up: { value: new THREE.Vector3(0, 0, 1) },
  };
}

const vertex = /* glsl */ `
  uniform float mode, projScale, sizeScale, minPx, spacing, viewsMax, sigmaMax, fixedPx, hasColor;
  uniform vec2 heightRange;
  uniform vec3 up;
  attribute vec3 color;
  attribute float views;
  attribute float sigma;
  varying vec3 vColor;
  vec3 ramp(float t) {
    t = clamp(t, 0.0, 1.0);
    return t < 0.5 ? vec3(2.0 * t, 0.8, 0.1) : vec3(1.0, 0.8 * (2.0 - 2.0 * t), 0.1);
  }
  void main() {
    vec4 world = modelMatrix * vec4(position, 1.0);
    vec4 mv = viewMatrix * world;
    gl_Position = projectionMatrix * mv;
    float px = fixedPx > 0.0 ? fixedPx : spacing * sizeScale * projScale / max(-mv.z, 1e-6);
    gl_PointSize = clamp(px, minPx, 24.0);
    if (mode < 0.5) vColor = hasColor > 0.5 ? color : vec3(0.8);
    else if (mode < 1.5) vColor = normalize(mat3(modelMatrix) * normal + 1e-6) * 0.5 + 0.5;
    else if (mode < 2.5) vColor = ramp(1.0 - (views - 2.0) / max(viewsMax - 2.0, 1.0));
    else if (mode < 3.5) vColor = ramp((dot(world.xyz, up) - heightRange.x) / max(heightRange.y - heightRange.x, 1e-6));
    else vColor = ramp(sigma / max(sigmaMax, 1e-12));
  }`;

const fragment = /* glsl */ `
  varying vec3 vColor;
  void main() {
    vec2 c = gl_PointCoord - 0.5;
    if (dot(c, c) > 0.25) discard;
    gl_FragColor = vec4(vColor, 1.0);
  }`;

/** A material for one point object; `spacing` in world units, or `fixedPx` > 0 for a constant pixel size. */
export function createPointMaterial(u: PointUniforms, spacing: number, hasColor: boolean, fixedPx = 0): THREE.ShaderMaterial {
  return new THREE.ShaderMaterial({
    uniforms: { ...u, spacing: { value: spacing }, fixedPx: { value: fixedPx }, hasColor: { value: hasColor ? 1 : 0 } },
    vertexShader: vertex, fragmentShader: fragment,
  });
}
