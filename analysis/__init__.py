"""Analysis: a run store in (:mod:`.load`), labelled tactile flow per segment out (:mod:`.run`,
``tactile-analyze``). See docs/architecture.md and docs/analysis.md."""
