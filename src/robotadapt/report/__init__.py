"""The only layer that draws or writes results (layer `report`): figures (:mod:`.figures`, :mod:`.sweep_figures`), HTML
pages (:mod:`.html`), saving a run (:mod:`.files`) and how a figure becomes a file (:mod:`.output`: format, dpi)."""
