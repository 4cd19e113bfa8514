"""``posturegen bench``: the benchmark families (:mod:`.families`), the planner-loop families
(:mod:`.reach`) and their fresh-process runs (:mod:`.planner`), the pass of problems never
seen (:mod:`.cold`) and its problems for a peer solver (:mod:`.peer`), batch scaling
(:mod:`.scaling`) and the Markdown tables (:mod:`.table`)."""
