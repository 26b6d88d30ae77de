// See glb.html. The mesh is drawn as its file says (glTF's +Y up), lit by a low directional
// light and a dim hemisphere light, seen obliquely from the south-east of its bounding box.
import * as THREE from 'three';
import { GLTFLoader } from 'three/addons/loaders/GLTFLoader.js';

try {
  const renderer = new THREE.WebGLRenderer({ antialias: true, preserveDrawingBuffer: true });
  renderer.setPixelRatio(1);
  renderer.setSize(window.innerWidth, window.innerHeight);
  document.body.appendChild(renderer.domElement);

  const scene = new THREE.Scene();
  scene.background = new THREE.Color('#0b1020');
  const gltf = await new GLTFLoader().loadAsync('/mesh.glb');
  scene.add(gltf.scene);

  let vertices = 0;
  let triangles = 0;
  let withNormals = 0;
  gltf.scene.traverse((o) => {
    if (!o.isMesh) return;
    const g = o.geometry;
    vertices += g.attributes.position.count;
    triangles += (g.index ? g.index.count : g.attributes.position.count) / 3;
    if (g.attributes.normal) withNormals++;
  });

  const box = new THREE.Box3().setFromObject(gltf.scene);
  const size = box.getSize(new THREE.Vector3());
  const centre = box.getCenter(new THREE.Vector3());
  const radius = size.length() / 2;
  const camera = new THREE.PerspectiveCamera(40, window.innerWidth / window.innerHeight, radius / 100, radius * 10);
  const dir = new THREE.Vector3(0.45, 0.65, 1).normalize();
  camera.position.copy(centre).addScaledVector(dir, (radius / Math.sin(THREE.MathUtils.degToRad(20))) * 0.9);
  camera.lookAt(centre);

  scene.add(new THREE.HemisphereLight('#c8d8ff', '#403020', 0.6));
  const sun = new THREE.DirectionalLight('#fff4e0', 2.2);
  sun.position.copy(centre).add(new THREE.Vector3(-1, 0.6, 0.4).multiplyScalar(radius));
  sun.target.position.copy(centre);
  scene.add(sun, sun.target);

  renderer.render(scene, camera);
  window.stats = { meshes: 0, vertices, triangles, withNormals, size: size.toArray(), centre: centre.toArray() };
  gltf.scene.traverse((o) => { if (o.isMesh) window.stats.meshes++; });
  window.ready = true;
} catch (e) {
  window.errors.push(`glb page: ${e?.stack ?? e}`);
  window.failed = String(e);
}
