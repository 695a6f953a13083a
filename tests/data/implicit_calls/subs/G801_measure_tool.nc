%G801_measure_tool
(stand-in: no tool setter here; the tool is taken as measured)
N10 #MSG ["G801: tool measured"]
N20 M17
