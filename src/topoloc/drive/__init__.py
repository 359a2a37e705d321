"""Route following under appearance change (Cai & Wan): the closed-loop driving simulator (:mod:`.lanes`,
:mod:`.simulator`), the expert and its demonstrations (:mod:`.expert`, :mod:`.demonstrations`), the Topo-DLM
controller (:mod:`.controller`) and teach and repeat in closed loop (:mod:`.closed_loop`)."""
