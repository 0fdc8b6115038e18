// Writes the files that splat-io's readers are tested on, with other implementations of the
// formats: spz-js (spz version 2, compressed .ply) and PlayCanvas splat-transform (spz
// versions 3 and 4, compressed .ply, glTF .glb with KHR_gaussian_splatting, SOG),
// GaussianSplats3D (.ksplat) and three.js's GLTFExporter (meshes with glTF materials). Run by `cargo xtask assets` as
//   node make.mjs OUT_DIR
// in a folder where `npm ci` installed package-lock.json; OUT_DIR/source.ply must exist.
import { mkdirSync, readFileSync, writeFileSync } from 'node:fs';
import { execFile, execFileSync } from 'node:child_process';
import { promisify } from 'node:util';
import { join } from 'node:path';
import { Readable } from 'node:stream';
import { loadPly, serializeSpz, serializeCompressedPly } from 'spz-js';

const out = process.argv[2];
const source = join(out, 'source.ply');

// spz-js: read the .ply, write spz version 2 and a compressed .ply.
const stream = () => Readable.toWeb(Readable.from([readFileSync(source)]));
writeFileSync(join(out, 'spz-js-v2.spz'), await serializeSpz(await loadPly(stream())));
writeFileSync(join(out, 'spz-js.compressed.ply'), serializeCompressedPly(await loadPly(stream())));

// splat-transform's command line: spz 3 and 4, compressed .ply.
const cli = join('node_modules', '@playcanvas', 'splat-transform', 'bin', 'cli.mjs');
const transform = (...args) => execFileSync(process.execPath, [cli, '-q', '-w', ...args], { stdio: 'inherit' });
transform(source, '--spz-version', '3', join(out, 'splat-transform-v3.spz'));
transform(source, '--spz-version', '4', join(out, 'splat-transform-v4.spz'));
transform(source, join(out, 'splat-transform.compressed.ply'));
// glTF with KHR_gaussian_splatting (.glb): linear scale, opacity after the sigmoid, the data
// turned a half turn about z into glTF's +Y-up axes.
transform(source, join(out, 'splat-transform.glb'));

// PlayCanvas SOG, on the CPU (`-g cpu`: no WebGPU adapter here): bundled (.sog) and as a
// folder (meta.json and its images), and splat-transform's own decoding of each. Each encode
// clusters for seconds on one core: the two run side by side.
const transformAsync = (...args) => promisify(execFile)(process.execPath, [cli, '-q', '-w', ...args]);
mkdirSync(join(out, 'sog'), { recursive: true });
await Promise.all([
    transformAsync('-g', 'cpu', source, join(out, 'splat-transform.sog')),
    transformAsync('-g', 'cpu', source, join(out, 'sog', 'meta.json')),
]);
transform(join(out, 'splat-transform.sog'), join(out, 'splat-transform-sog-decoded.ply'));
transform(join(out, 'sog', 'meta.json'), join(out, 'splat-transform-sog-folder-decoded.ply'));

// An antialiased capture as Postshot marks it (`comment antialiased 1`), and what splat-transform
// writes of it: Brush's `SplatRenderMode: mip` in a .ply and a compressed .ply, the antialiased
// flag (0x1) in spz 3 and 4.
const plain = readFileSync(source);
const at = plain.indexOf('element vertex');
const antialiased = join(out, 'antialiased.ply');
writeFileSync(antialiased, Buffer.concat([plain.subarray(0, at), Buffer.from('comment antialiased 1\n'), plain.subarray(at)]));
transform(antialiased, join(out, 'splat-transform-antialiased.ply'));
transform(antialiased, join(out, 'splat-transform-antialiased.compressed.ply'));
transform(antialiased, '--spz-version', '3', join(out, 'splat-transform-antialiased-v3.spz'));
transform(antialiased, '--spz-version', '4', join(out, 'splat-transform-antialiased-v4.spz'));
// The SOG one only marks the mode (`"model": "antialiased"`): it is made of the first 256
// splats, which cluster in a moment.
const header = plain.subarray(0, plain.indexOf('end_header\n') + 'end_header\n'.length).toString();
const stride = 4 * (header.match(/^property float /gm) || []).length;
const few = 256;
const fewHeader = header.replace(/element vertex \d+/, `element vertex ${few}`).replace('element vertex', 'comment antialiased 1\nelement vertex');
const fewAntialiased = join(out, 'antialiased-256.ply');
writeFileSync(fewAntialiased, Buffer.concat([Buffer.from(fewHeader), plain.subarray(header.length, header.length + few * stride)]));
transform('-g', 'cpu', fewAntialiased, join(out, 'splat-transform-antialiased.sog'));

// mkkellogg's GaussianSplats3D .ksplat, as its util/create-ksplat.js writes one (that script is
// not in the npm package; these are its calls): the .ply parsed at SH degree 2 (the format's
// most), then SplatBufferGenerator's standard partition at compression levels 0 (f32), 1 (f16,
// 16-bit positions) and 2 (as 1, with 8-bit SH); and level 1 in three sections of small blocks
// and buckets, so that files with several sections and partly filled buckets are read. Then
// splat-transform's own decoding of each.
const GaussianSplats3D = await import('@mkkellogg/gaussian-splats-3d');
const ksplat = (level, sectionSize, blockSize, bucketSize, name) => {
    const data = readFileSync(source);
    const buffer = data.buffer.slice(data.byteOffset, data.byteOffset + data.byteLength);
    const splats = GaussianSplats3D.PlyParser.parseToUncompressedSplatArray(buffer, 2);
    const generator = GaussianSplats3D.SplatBufferGenerator.getStandardGenerator(
        undefined, level, sectionSize, undefined, blockSize, bucketSize);
    writeFileSync(join(out, name), Buffer.from(generator.generateFromUncompressedSplatArray(splats).bufferData));
    transform(join(out, name), join(out, name.replace('.ksplat', '-decoded.ply')));
};
for (const level of [0, 1, 2]) ksplat(level, 0, undefined, undefined, `gaussian-splats-3d-${level}.ksplat`);
ksplat(1, 1000, 0.5, 64, 'gaussian-splats-3d-sections.ksplat');

// three.js's GLTFExporter: seven quads, one a material, as a three.js user exports them (.glb);
// the last blends with RGBA vertex colours.
// tests/tests/formats.rs names the same parameters. Colours are set in three.js's linear working
// space, so the exporter writes them as given. Node has Blob but no FileReader, through which
// the exporter reads its Blob.
globalThis.FileReader ??= class {
    readAsArrayBuffer(blob) {
        blob.arrayBuffer().then((bytes) => {
            this.result = bytes;
            this.onloadend();
        });
    }
};
const THREE = await import('three');
const { GLTFExporter } = await import('three/examples/jsm/exporters/GLTFExporter.js');
const rgb = (r, g, b) => new THREE.Color().setRGB(r, g, b, THREE.LinearSRGBColorSpace);
const materials = [
    new THREE.MeshStandardMaterial({ color: rgb(0.5, 0.25, 0.125), metalness: 0, roughness: 0.5 }),
    new THREE.MeshStandardMaterial({ color: rgb(0.2, 0.4, 0.6), transparent: true, opacity: 0.4, metalness: 0.25, roughness: 0.3 }),
    new THREE.MeshStandardMaterial({ color: rgb(0.9, 0.9, 0.9), alphaTest: 0.5, opacity: 0.3 }),
    new THREE.MeshPhysicalMaterial({ color: rgb(1, 1, 1), transmission: 0.8, ior: 1.33, metalness: 0.5, roughness: 0.1 }),
    new THREE.MeshStandardMaterial({ color: rgb(0.5, 0.5, 0), emissive: rgb(0.25, 1, 0.5), emissiveIntensity: 4 }),
    new THREE.MeshBasicMaterial({ color: rgb(0.3, 0.6, 0.9) }),
    new THREE.MeshStandardMaterial({ color: rgb(0.7, 0.7, 0.7), transparent: true, opacity: 0.5, vertexColors: true }),
];
const world = new THREE.Scene();
const rgba = new THREE.Float32BufferAttribute([1, 0, 0, 0.2, 0, 1, 0, 0.4, 0, 0, 1, 0.6, 1, 1, 1, 0.8], 4);
materials.forEach((material, i) => {
    const geometry = new THREE.PlaneGeometry(1, 1);
    if (material.vertexColors) geometry.setAttribute('color', rgba);
    const quad = new THREE.Mesh(geometry, material);
    quad.position.set(1.5 * i, 0, 0);
    world.add(quad);
});
const glb = await new GLTFExporter().parseAsync(world, { binary: true });
writeFileSync(join(out, 'three-materials.glb'), Buffer.from(glb));
