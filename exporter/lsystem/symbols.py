"""Built-in `@` commands understood by the turtle: name -> allowed argument
counts. Grammar parsing rejects unknown `@` commands and wrong counts, so a
typo such as `@densty(600)` is an error instead of being silently ignored."""

from __future__ import annotations

AT_COMMANDS: dict[str, tuple[int, ...]] = {
    "@density": (1,),  # green wood density, kg/m^3
    "@modulus": (1,),  # Young's modulus, Pa
    "@ei": (1,),  # bending stiffness override, N*m^2 (0 = derive from modulus)
    "@stiffness": (1,),  # joint stiffness override, N*m/rad (0 = derive)
    "@damping": (1,),  # structural damping ratio of the first mode
    "@cone": (1,),  # joint cone half-angle, degrees
    "@strength": (1,),  # breaking bending moment, N*m (0 = unbreakable)
    "@rupture": (1,),  # modulus of rupture, Pa (0 = off); strength = MOR*pi*D^3/32
    "@leaves": (1, 2),  # leaf type (0 = none) [, leaf size in metres]
    "@tropism": (1, 4),  # elasticity, or x, y, z, elasticity
    "@width": (1,),  # same as !(w)
    "@roll": (0,),  # same as $
    "@twig": (0,),  # F draws twigs on the segment under the turtle, to the bracket's end
}
