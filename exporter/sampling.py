"""How a bake samples the motion, a contract between the simulation, which
records the samples, and the bake and its exporters, which keep them: every
frame, and between two frames the sub-frame samples of a bone that turns
more than FAST_TURN_DEG from one frame to the next (a fast fall, a blast)."""

# degrees: a segment turning more than this between two frames is fast there;
# the simulation records sub-frame samples for it, the exporters keep them
FAST_TURN_DEG = 45.0
