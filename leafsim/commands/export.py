"""``leafsim export``: one leaf simulated and written as a mesh (glTF with the drying as
morph targets, OBJ, PLY)."""

from __future__ import annotations

from pathlib import Path

from leafsim.appearance.view import LeafView
from leafsim.base.errors import LeafsimError
from leafsim.base.fileio import check_output, not_an_input, output_target
from leafsim.commands.common import Progress, emit, ready_kernels, species_inputs, species_params, stop_of, warn
from leafsim.export.mesh import export_mesh, format_of, side_files
from leafsim.pipeline import build_leaf
from leafsim.sim.run import Run, Stop


#: an animation with more key frames than this says so (each is a morph target: a copy of every vertex)
MANY_TARGETS = 200


def _check(args) -> str:
    if not str(args.out).strip():
        raise LeafsimError("--out '': expected a mesh file name (.glb, .gltf, .obj or .ply)")
    check_output(args.out, "mesh")  # a folder, a device or an unwritable place: now, not after the drying
    fmt = format_of(args.out, args.format, "--format")
    if args.every < 0:
        raise LeafsimError(f"--every {args.every}: expected a non-negative frame interval")
    if args.every and fmt in ("obj", "ply"):
        raise LeafsimError(f"--every needs --format glb or gltf ({fmt} holds one static shape)")
    if args.texture == "auto":  # a still as the window draws it; an animation and PLY per vertex
        args.texture = "colours" if args.every or fmt == "ply" else "baked"
    if args.texture == "baked" and args.every:
        raise LeafsimError(f"--texture baked holds one state's colour (a texture cannot change with the key frames): "
                           f"leave out --every {args.every}, or use --texture colours for the drying animation")
    if fmt == "ply" and args.texture != "colours":
        raise LeafsimError(f"--texture {args.texture}: PLY carries vertex colours, not a texture (use --texture colours, "
                           "or --format glb / obj)")
    if args.frames is None and args.until is None:
        if args.every:  # key frames of a run that does not run: an animation without a key
            raise LeafsimError(f"--every {args.every} needs --frames N or --until dry (how long the animated drying runs)")
        args.frames = 0  # the fresh leaf
    if args.every and args.until is None and args.frames == 0:
        raise LeafsimError(f"--every {args.every} with --frames 0: the fresh leaf alone has no drying to animate "
                           "(give --frames N or --until dry, or leave --every out)")
    stop_of(args)
    folder = Path(args.out).parent
    if not folder.is_dir():
        raise LeafsimError(f"--out {args.out}: folder {folder} does not exist")
    # the files written beside the mesh, checked now too (a folder named x.bin failed after the drying)
    for path, what in side_files(args.out, fmt, args.texture):
        output_target(path, what)
    return fmt


def _written(out, fmt: str, texture: str = "colours") -> list:
    """Every file an export to ``out`` writes."""
    return [Path(out), *(p for p, _ in side_files(out, fmt, texture))]


def key_frames(run: Run, stop: Stop | int, every: int, progress: Progress | None = None) -> list:
    """Simulate until ``stop`` (a :class:`Stop` or a frame number); the states every ``every``
    frames (with the first and the last), or the last state alone when ``every`` is 0."""
    keys = [run.state.copy()]
    try:
        for _ in run.frames(stop if isinstance(stop, Stop) else Stop(frames=stop)):
            if every and run.state.frame % every == 0:
                keys.append(run.state.copy())
            if progress is not None:
                progress.update()
    finally:
        if progress is not None:
            progress.close()
    if not every:
        return [run.state]
    if keys[-1].frame != run.state.frame:
        keys.append(run.state.copy())
    return keys


def cmd_export(args):
    fmt = _check(args)
    sp, params = species_params(args, effects=True)
    for path in _written(args.out, fmt, args.texture):
        not_an_input(path, species_inputs(sp), "--out")
    if args.texture == "photo" and sp.image is None:
        raise LeafsimError(f"--texture photo: species '{sp.key}' has no photo (drawn outline)")
    ready_kernels()
    model = build_leaf(sp, params, args.seed).model
    run = Run(model, params, seed=args.seed)
    until = stop_of(args)
    keys = key_frames(run, until, args.every, Progress(args, run, until, sp.key))
    if args.every and len(keys) - 1 > MANY_TARGETS:
        # (--every 1 over a whole drying wrote 2572 targets: a 290 MB glb, 2.9 GB of memory to write it)
        warn(f"--every {args.every}: {len(keys) - 1} morph targets, each a copy of every vertex; the file and Blender's "
             f"shape keys grow with them (--every {max(args.every, run.state.frame // 100)} gives about 100)")
    if args.every and len(keys) < 2:  # (--until water=1 or season=0 hold at the fresh leaf)
        raise LeafsimError(f"--every {args.every} with --until {args.until}: the run stopped at frame {run.state.frame}, so "
                           "there is no drying to animate (give a later --until, or leave --every out)")
    view = LeafView.of_species(sp, model, params, pigments0=run.sim.state().pigments)
    if args.texture == "photo" and fmt == "obj" and run.state.frame > 0 and run.sim.effects.get("colour", False):
        # an OBJ holds the photo as its texture and nothing to age it by (a glTF carries _AGEING)
        warn(f"--texture photo with OBJ: the texture is the photo as the leaf looked when photographed, not its colour "
             f"at frame {run.state.frame} (OBJ cannot carry the ageing); use --texture baked, or glb / gltf")
    water = model.water_fraction(run.state.particle_water)
    about = {"species": sp.key, "seed": args.seed, "frame": run.state.frame, "time_s": round(float(run.state.time), 9),
             "water_fraction": round(water, 6)}
    rep = export_mesh(model, keys, args.out, format=fmt, params=params, view=view, layers=args.layers,
                      veins=args.veins, texture=args.texture, name=f"{sp.key}-seed{args.seed}", extras={"leafsim": about},
                      keep=species_inputs(sp))
    rep.update(species=sp.key, seed=args.seed, frames=run.state.frame, water_fraction=round(water, 6), texture=args.texture)
    if fmt in ("glb", "gltf", "obj"):
        # the add-on that brings into Blender what its importers drop: a glTF's colour morphs and
        # photo ageing, an OBJ's vertex colours and the normal map's colour space
        from leafsim.export import blender_import

        rep["blender_addon"] = str(Path(blender_import.__file__).resolve())
    counts = ", ".join(f"{k} {v['vertices']} vertices / {v['triangles']} triangles" for k, v in rep["meshes"].items())
    shown = "the base mesh; earlier key frames as morph targets" if rep["targets"] else "one frame"
    emit(args, rep, f"{sp.key}: frame {run.state.frame}, {100 * water:.1f} % of the blade's water left ({shown}); "
                    f"{counts}, {rep['targets']} morph targets -> {', '.join(rep['files'])}"
                    + (f"; removed what an earlier export left there and this one did not write: {', '.join(rep['removed'])}"
                       if rep.get("removed") else ""))
