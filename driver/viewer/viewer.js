// guidebake view: the baked level through three.js's own lightmap path (docs/engines.md).
//
// view.json (written by `guidebake view`) names the level (level.glb: the scene with its
// lightmap UVs as TEXCOORD_1, and each mesh node's page, scale and offset in
// extras.guidebake_lightmap), one or two lightmaps (each a list of half-float EXR pages holding
// irradiance E), the start camera, the exposure and the sky's colour. Every lightmapped
// material is a MeshStandardMaterial whose lightMap is its page: three.js adds
// lightMap × lightMapIntensity to the irradiance and shades it with the Lambert BRDF
// albedo / π (lights_fragment_maps, RE_IndirectDiffuse_Physical), so the intensity is 1 and
// a surface shows albedo × E / π, as `guidebake render` does. Tone mapping is three.js's
// Reinhard (exposure, then x / (1 + x)) and the output sRGB, also as `render`.
//
// URL parameters: ?shot hides the controls (screenshots), ?exposure=X sets the exposure.
import * as THREE from 'three';
import { GLTFLoader } from 'three/addons/loaders/GLTFLoader.js';
import { EXRLoader } from 'three/addons/loaders/EXRLoader.js';
import { OrbitControls } from 'three/addons/controls/OrbitControls.js';

const params = new URLSearchParams(location.search);
if (params.has('shot')) document.body.classList.add('shot');

function fail(message) {
  const box = document.getElementById('error');
  box.textContent = message;
  box.hidden = false;
  document.title = 'guidebake view: error';
  console.error(message);
}

async function fetchJson(url) {
  const response = await fetch(url);
  if (!response.ok) throw new Error(`${url}: ${response.status} ${response.statusText}`);
  return response.json();
}

// The lightmap binding of a mesh: its node's extras (GLTFLoader keeps a node's extras as the
// userData of the node's object, the mesh itself or the group of its primitives).
function bindingOf(object) {
  for (let o = object; o; o = o.parent) {
    if (o.userData && o.userData.guidebake_lightmap) return o.userData.guidebake_lightmap;
  }
  return null;
}

// A page of lightmap `k` placed for one binding. The UVs are glTF's, v down from the image's
// top; EXRLoader stores the rows bottom-up (texture v up), so v is turned over here, after
// the binding's own `uv · scale + offset`.
function placedPage(page, binding) {
  const t = page.clone();
  const [sx, sy] = binding.scale || [1, 1];
  const [ox, oy] = binding.offset || [0, 0];
  t.repeat.set(sx, -sy);
  t.offset.set(ox, 1 - oy);
  t.needsUpdate = true;
  return t;
}

// The scene lit by one lightmap: each lightmapped mesh gets a copy of its material bound to
// its page (one copy per material, page and placement).
function litCopy(root, lightmap, intensity) {
  const scene = root.clone(true);
  const copies = new Map();
  scene.traverse((object) => {
    if (!object.isMesh) return;
    const binding = bindingOf(object);
    if (!binding || !object.geometry.getAttribute('uv1')) return;
    const page = lightmap.pages[binding.page];
    if (!page) throw new Error(`a mesh's lightmap page ${binding.page} is not in ${lightmap.name}`);
    const key = `${object.material.uuid}/${binding.page}/${binding.scale}/${binding.offset}`;
    let material = copies.get(key);
    if (!material) {
      material = object.material.clone();
      // The bake treats every surface as diffuse with the base colour as albedo: no
      // metal, and no specular without lights or an environment.
      material.metalness = 0;
      material.lightMap = placedPage(page, binding);
      material.lightMap.channel = 1; // TEXCOORD_1, GLTFLoader's uv1
      material.lightMapIntensity = intensity;
      copies.set(key, material);
    }
    object.material = material;
  });
  return scene;
}

async function main() {
  const view = await fetchJson('view.json');
  let renderer;
  try {
    renderer = new THREE.WebGLRenderer({ antialias: true, preserveDrawingBuffer: true });
  } catch (e) {
    throw new Error(`WebGL is not available in this browser: ${e.message}`);
  }
  renderer.setPixelRatio(params.has('shot') ? 1 : window.devicePixelRatio);
  renderer.setSize(window.innerWidth, window.innerHeight);
  renderer.toneMapping = THREE.ReinhardToneMapping;
  renderer.outputColorSpace = THREE.SRGBColorSpace;
  renderer.setScissorTest(true);
  document.body.appendChild(renderer.domElement);
  addEventListener('resize', () => renderer.setSize(window.innerWidth, window.innerHeight));

  const exr = new EXRLoader(); // half-float RGBA, linear
  const [gltf, ...lightmaps] = await Promise.all([
    new GLTFLoader().loadAsync(view.scene),
    ...view.lightmaps.map(async (lm) => ({
      name: lm.name,
      pages: await Promise.all(lm.pages.map((url) => exr.loadAsync(url))),
    })),
  ]);
  for (const lm of lightmaps) {
    for (const page of lm.pages) {
      page.colorSpace = THREE.LinearSRGBColorSpace;
      page.minFilter = THREE.LinearFilter; // bilinear, no mipmaps: charts do not bleed
      page.magFilter = THREE.LinearFilter;
      page.generateMipmaps = false;
      page.wrapS = page.wrapT = THREE.ClampToEdgeWrapping;
    }
  }
  const scenes = lightmaps.map((lm) => litCopy(gltf.scene, lm, view.intensity));
  lightmaps.forEach((lm, k) => {
    const label = document.createElement('div');
    label.className = 'label';
    label.textContent = lm.name;
    label.style.left = `calc(${(100 * k) / lightmaps.length}% + 8px)`;
    document.body.appendChild(label);
  });

  const c = view.camera;
  const camera = new THREE.PerspectiveCamera(c.fov, 1, c.near, c.far);
  const controls = new OrbitControls(camera, renderer.domElement);
  function resetView() {
    camera.position.fromArray(c.eye);
    controls.target.fromArray(c.target);
    camera.lookAt(controls.target);
    controls.update();
  }
  resetView();
  document.getElementById('reset').addEventListener('click', resetView);

  // Exposure: a slider in stops around the start exposure (?exposure= overrides it).
  const start = Number(params.get('exposure')) || view.exposure;
  const slider = document.getElementById('exposure');
  const shown = document.getElementById('exposure-value');
  const sky = new THREE.Color();
  function setExposure(stops) {
    slider.value = stops;
    renderer.toneMappingExposure = start * 2 ** stops;
    shown.textContent = renderer.toneMappingExposure.toPrecision(3);
    // The clear colour is not tone-mapped by three.js: map the sky's radiance as `render`
    // does (Reinhard at this exposure; the output's sRGB encoding follows).
    const e = renderer.toneMappingExposure;
    const reinhard = (x) => (x * e) / (1 + x * e);
    sky.setRGB(...view.sky.map(reinhard), THREE.LinearSRGBColorSpace);
    renderer.setClearColor(sky);
  }
  setExposure(0);
  slider.addEventListener('input', () => setExposure(Number(slider.value)));

  // Walking: the keys move the eye and the orbit's centre together, along the ground.
  const held = new Set();
  addEventListener('keydown', (e) => {
    if (e.key === '+' || e.key === '=') setExposure(Number(slider.value) + 0.25);
    else if (e.key === '-') setExposure(Number(slider.value) - 0.25);
    else held.add(e.code);
  });
  addEventListener('keyup', (e) => held.delete(e.code));
  addEventListener('blur', () => held.clear());
  const clock = new THREE.Clock();
  const forward = new THREE.Vector3();
  const right = new THREE.Vector3();
  const step = new THREE.Vector3();
  function walk(dt) {
    const axis = (plus, minus) => plus.some((k) => held.has(k)) - minus.some((k) => held.has(k));
    const ahead = axis(['KeyW', 'ArrowUp'], ['KeyS', 'ArrowDown']);
    const aside = axis(['KeyD', 'ArrowRight'], ['KeyA', 'ArrowLeft']);
    const rise = axis(['KeyE', 'PageUp'], ['KeyQ', 'PageDown']);
    if (!ahead && !aside && !rise) return;
    camera.getWorldDirection(forward);
    forward.y = 0;
    forward.normalize();
    right.crossVectors(forward, camera.up).normalize();
    const speed = view.walk_speed * (held.has('ShiftLeft') || held.has('ShiftRight') ? 4 : 1);
    step.set(0, 0, 0)
      .addScaledVector(forward, ahead)
      .addScaledVector(right, aside)
      .addScaledVector(camera.up, rise)
      .multiplyScalar(speed * dt);
    camera.position.add(step);
    controls.target.add(step);
  }

  let frames = 0;
  renderer.setAnimationLoop(() => {
    walk(Math.min(clock.getDelta(), 0.1));
    controls.update();
    const { width, height } = renderer.getSize(new THREE.Vector2());
    const part = Math.floor(width / scenes.length);
    camera.aspect = part / height;
    camera.updateProjectionMatrix();
    scenes.forEach((scene, k) => {
      const w = k === scenes.length - 1 ? width - k * part : part;
      renderer.setViewport(k * part, 0, w, height);
      renderer.setScissor(k * part, 0, w, height);
      renderer.render(scene, camera);
    });
    if (++frames === 2) document.title = 'guidebake view: ready';
  });
}

main().catch((e) => fail(`guidebake view: ${e.message}`));
