"""The only layer that draws or writes results (layer `report`): figures (:mod:`.figures`, :mod:`.sweep_figures`), HTML
pages (:mod:`.html`) and saving a run (:mod:`.files`)."""
