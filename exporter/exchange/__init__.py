"""Output formats, one module per job: `mesh` (tree geometry and skinning),
`anim` (joint channels, keyframe reduction), `axes` (Z up -> Y up), `gltf`,
`obj`, `usd` (optional usd-core), `abc` (Alembic, optional alembic3d).
`exporter.export` drives them."""
