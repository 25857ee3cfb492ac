"""Strike, sliding/rolling breakpoint and rest; parabola and line fits."""
