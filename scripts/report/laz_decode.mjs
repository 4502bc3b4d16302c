#!/usr/bin/env node
// Decodes a LAZ (or LAS) file with laz-perf, hobuinc's LASzip decoder compiled to WebAssembly
// (npm laz-perf@0.0.7, installed by `scripts/setup.sh --tests`), an implementation independent of
// ours: the check that bench/points/laz_writer.cpp writes LAZ that LAZ readers read.
//
//   node scripts/report/laz_decode.mjs FILE [--raw OUT] [--modules DIR]
//
// Prints one line of JSON: {"points", "format", "record_length", "sha256"} (the SHA-256 of the
// decoded point records, concatenated as LAS stores them). --raw also writes those records to
// OUT (written to a temporary name, then renamed). --modules: the directory whose node_modules
// holds laz-perf; default $CATPAQ_NPM_DIR, else ~/.cache/catpaq-npm (where setup installs it).
// Exit status 0 done, 1 the file or laz-perf failed, 2 usage error.
import { createHash } from 'node:crypto';
import { readFileSync, renameSync, writeFileSync, unlinkSync } from 'node:fs';
import { createRequire } from 'node:module';
import os from 'node:os';
import path from 'node:path';

function usage(message) {
  process.stderr.write(`laz_decode: ${message}\nusage: node laz_decode.mjs FILE [--raw OUT] [--modules DIR]\n`);
  process.exit(2);
}

function parseArguments(argv) {
  const options = { file: null, raw: null, modules: process.env.CATPAQ_NPM_DIR || path.join(os.homedir(), '.cache', 'catpaq-npm') };
  for (let i = 0; i < argv.length; ++i) {
    const a = argv[i];
    if (a === '--raw' || a === '--modules') {
      if (i + 1 >= argv.length) usage(`${a} needs a value`);
      options[a.slice(2)] = argv[++i];
    } else if (a.startsWith('--')) {
      usage(`unknown option ${a}`);
    } else if (options.file === null) {
      options.file = a;
    } else {
      usage(`one file only (got ${options.file} and ${a})`);
    }
  }
  if (options.file === null) usage('no file given');
  return options;
}

function die(message) {
  process.stderr.write(`laz_decode: ${message}\n`);
  process.exit(1);
}

// laz-perf from DIR/node_modules, whatever directory this script runs from.
function loadLazPerf(modules) {
  const require = createRequire(path.join(path.resolve(modules), 'package.json'));
  try {
    return require('laz-perf');
  } catch (e) {
    die(`laz-perf is not installed under ${modules}/node_modules (scripts/setup.sh --tests installs it): ${e.message}`);
  }
}

// A C++ exception from the WebAssembly module arrives as a pointer or an object; its message
// where laz-perf's build keeps one (0.0.7's does not: it was built without exception catching).
function describe(module, e) {
  const text = e instanceof Error ? e.message : String(e);
  if (/Exception catching is disabled/.test(text)) return 'laz-perf refused the file (its WebAssembly build keeps no message)';
  if (typeof e === 'number' && module.getExceptionMessage) return module.getExceptionMessage(e).join(': ');
  return text;
}

const options = parseArguments(process.argv.slice(2));
const { createLazPerf } = loadLazPerf(options.modules);
let bytes;
try {
  bytes = readFileSync(options.file);
} catch (e) {
  die(`cannot read ${options.file}: ${e.message}`);
}
const module = await createLazPerf();
const filePointer = module._malloc(bytes.length);
module.HEAPU8.set(bytes, filePointer);
const reader = new module.LASZip();
try {
  reader.open(filePointer, bytes.length);
} catch (e) {
  die(`laz-perf cannot open ${options.file}: ${describe(module, e)}`);
}
const count = Number(reader.getCount());
const recordLength = reader.getPointLength();
const format = reader.getPointFormat();
const pointPointer = module._malloc(recordLength);
const hash = createHash('sha256');
const records = options.raw ? Buffer.alloc(count * recordLength) : null;
try {
  for (let i = 0; i < count; ++i) {
    reader.getPoint(pointPointer);
    // HEAPU8 is re-read each time: the module's memory may grow and replace it.
    const record = module.HEAPU8.subarray(pointPointer, pointPointer + recordLength);
    hash.update(record);
    if (records) records.set(record, i * recordLength);
  }
} catch (e) {
  die(`laz-perf failed decoding ${options.file}: ${describe(module, e)}`);
}
if (records) {
  const temporary = `${options.raw}.tmp.${process.pid}`;
  try {
    writeFileSync(temporary, records);
    renameSync(temporary, options.raw);
  } catch (e) {
    try { unlinkSync(temporary); } catch {}
    die(`cannot write ${options.raw}: ${e.message}`);
  }
}
reader.delete();
module._free(pointPointer);
module._free(filePointer);
process.stdout.write(JSON.stringify({ points: count, format, record_length: recordLength, sha256: hash.digest('hex') }) + '\n');
