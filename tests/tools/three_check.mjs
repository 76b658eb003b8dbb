// Load a glTF binary with three.js's own GLTFLoader (under Node, no DOM) and
// report what a three.js user gets: which node names the loader rewrote
// (PropertyBinding.sanitizeNodeName strips [ ] . : / and spaces, then
// createUniqueName suffixes duplicates `_N`), and, with --times, every joint
// node's world position after AnimationMixer.setTime(t) (m, Y up).
// Usage: node three_check.mjs FILE.glb [--times t1,t2,...]  ->  one JSON object.
import fs from "fs";
import * as THREE from "three";
import { GLTFLoader } from "three/examples/jsm/loaders/GLTFLoader.js";

const file = process.argv[2];
const ti = process.argv.indexOf("--times");
const times = ti > 0 ? process.argv[ti + 1].split(",").map(Number) : [];
const bytes = fs.readFileSync(file);
const json = JSON.parse(bytes.subarray(20, 20 + bytes.readUInt32LE(12)).toString("utf8"));
const buffer = bytes.buffer.slice(bytes.byteOffset, bytes.byteOffset + bytes.byteLength);

class NodeImages extends GLTFLoader {}  // textures: no DOM here; geometry and names only
const loader = new NodeImages();
loader.register((parser) => {
  parser.loadTexture = async () => null;
  return { name: "treebake_no_images" };
});

loader.parse(buffer, "", (gltf) => {
  const byNode = new Map();
  for (const [object, assoc] of gltf.parser.associations) {
    if (object.isObject3D && assoc.nodes !== undefined) byNode.set(assoc.nodes, object);
  }
  const rewritten = [];
  const jsonNodes = json.nodes || [];
  jsonNodes.forEach((n, i) => {
    const obj = byNode.get(i);
    const got = obj ? obj.name : null;
    if (got !== (n.name || "")) rewritten.push({ node: i, name: n.name, three: got });
  });
  const names = jsonNodes.map((n, i) => (byNode.get(i) || {}).name);
  const duplicates = names.filter((n, i) => names.indexOf(n) !== i);
  const poses = {};
  if (times.length && gltf.animations.length) {
    const mixer = new THREE.AnimationMixer(gltf.scene);
    // play once and hold the end (looping would wrap t = duration to 0)
    const action = mixer.clipAction(gltf.animations[0]);
    action.setLoop(THREE.LoopOnce);
    action.clampWhenFinished = true;
    action.play();
    const joints = new Set((json.skins || []).flatMap((s) => s.joints));
    for (const t of times) {
      mixer.setTime(t);
      gltf.scene.updateMatrixWorld(true);
      const out = {};
      for (const j of joints) {
        const p = new THREE.Vector3().setFromMatrixPosition(byNode.get(j).matrixWorld);
        out[jsonNodes[j].name] = [p.x, p.y, p.z];
      }
      poses[t] = out;
    }
  }
  process.stdout.write(JSON.stringify({ nodes: jsonNodes.length, rewritten, duplicates,
                                        duration: gltf.animations.map((a) => a.duration),
                                        poses }) + "\n");
}, (err) => { process.stderr.write(String(err) + "\n"); process.exit(1); });
