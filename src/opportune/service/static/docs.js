// A readable page of the OpenAPI document (/openapi.json), drawn here: nothing fetched from elsewhere.
"use strict";

function node(tag, text, cls) {
  const e = document.createElement(tag);
  if (text !== undefined) e.textContent = text;
  if (cls) e.className = cls;
  return e;
}

function resolve(spec, schema) {
  if (schema && schema.$ref) return resolve(spec, schema.$ref.split("/").slice(1).reduce((o, k) => o[k], spec));
  return schema;
}

// Text with `inline code` as <code> elements (never as HTML: the text is the document's).
function prose(tag, text, cls) {
  const e = node(tag, undefined, cls);
  String(text || "").split("`").forEach((piece, i) => {
    e.append(i % 2 ? node("code", piece) : document.createTextNode(piece));
  });
  return e;
}

// The example a body shows: the document's own (a media type's first example, or the schema's),
// else one made from the schema.
function mediaExample(spec, media) {
  const named = media.examples && Object.values(media.examples)[0];
  if (named && named.value !== undefined) return named.value;
  if (media.example !== undefined) return media.example;
  return example(spec, media.schema);
}

function example(spec, schema, depth = 0) {
  schema = resolve(spec, schema || {});
  if (depth > 4 || !schema) return null;
  if (Array.isArray(schema.examples) && schema.examples.length) return schema.examples[0];
  if (schema.example !== undefined) return schema.example;
  if (schema.anyOf) return example(spec, schema.anyOf.find((s) => s.type !== "null") || schema.anyOf[0], depth + 1);
  if (schema.oneOf) return example(spec, schema.oneOf[schema.oneOf.length - 1], depth + 1);
  if (schema.enum) return schema.enum[0];
  if (schema.type === "object" || schema.properties) {
    const out = {};
    for (const [k, v] of Object.entries(schema.properties || {})) out[k] = example(spec, v, depth + 1);
    return out;
  }
  if (schema.type === "array") return [example(spec, schema.items, depth + 1)].filter((x) => x !== null);
  if (schema.default !== undefined) return schema.default;
  return { string: "…", integer: 0, number: 0, boolean: false }[schema.type] ?? "…";
}

async function main() {
  const spec = await (await fetch("/openapi.json")).json();
  const intro = document.getElementById("intro");
  intro.append(node("h2", `${spec.info.title} ${spec.info.version}`), prose("p", spec.info.summary),
               prose("p", spec.info.description));
  const ops = document.getElementById("ops");
  for (const [path, methods] of Object.entries(spec.paths)) {
    for (const [method, op] of Object.entries(methods)) {
      const card = node("section", undefined, "op");
      const h = node("h3");
      h.append(node("span", method.toUpperCase(), "method " + method), document.createTextNode(" " + path));
      card.append(h, prose("p", op.summary));
      const params = (op.parameters || []).map((p) => `${p.in} ${p.name}${p.required ? " (required)" : ""}: ${p.description || ""}`);
      if (params.length) card.append(node("pre", params.join("\n")));
      const body = op.requestBody && op.requestBody.content;
      if (body) {
        for (const [type, media] of Object.entries(body)) {
          const ex = mediaExample(spec, media);
          card.append(node("p", `body (${type})`, "muted small"),
                      node("pre", typeof ex === "string" ? ex : JSON.stringify(ex, null, 2)));
        }
      }
      const codes = Object.entries(op.responses || {}).map(([c, r]) => `${c} ${r.description || ""}`);
      card.append(prose("p", "responses: " + codes.join(" · "), "muted small"));
      ops.append(card);
    }
  }
}

document.addEventListener("DOMContentLoaded", main);
