"""How an engine's steps are taken — on one process or over MPI ranks — behind one small interface.

An :class:`~de_domain.engine.Engine` holds a run object, ``engine.runner``: a :class:`SerialRun`,
or a :class:`de_domain.distributed.DistributedRun` when the engine was given a communicator. The
engine asks its run object for the steps and for every operation whose result depends on other
ranks; it never calls MPI itself. Both kinds offer:

* ``run(engine, nsteps)`` — the steps, made through the engine's public step interface
  (:meth:`Engine.boundaries`, :meth:`Engine.book_boundary_jumps`, :meth:`Engine.update_lists`,
  :meth:`Engine.advance` for a serial run; :meth:`Engine.lists_due`, :meth:`Engine.step_on_copies`,
  :meth:`Engine.install_rows`, :meth:`Engine.write_back` … for a distributed one);
* ``wall_totals(engine)`` — each plane wall's force, summed over all particles in the serial order;
* ``is_root`` — does this process book the global terms once and write the shared files?
* ``minimum(x)``, ``maximum(x)``, ``broadcast(x)`` (the root's value), ``concatenate(a)``
  (every rank's array, in rank order), ``barrier()``;
* ``books(engine, books)`` (the energy books of all ranks), ``owned_rows(engine)`` (every
  rank's owned particles in global-id order), ``contact_records(engine)`` (every rank's
  contact history).

A serial run's collectives are the identity: a caller writes one code path for both.
"""
from __future__ import annotations


class SerialRun:
    """The steps of one process: lists rebuilt when due, then fused steps until the next
    rebuild or spatial-order refresh (:func:`de_domain.fused.advance`)."""

    is_root = True

    def run(self, engine, nsteps):
        done = 0
        while done < nsteps:
            boundaries = engine.boundaries()
            engine.book_boundary_jumps(boundaries)
            engine.update_lists(boundaries)
            done += engine.advance(min(nsteps - done, engine.steps_before_reorder()), boundaries)

    def wall_totals(self, engine):
        """Nothing to do: a serial run sums the wall forces at the end of every run."""

    def minimum(self, value):
        return value

    def maximum(self, value):
        return value

    def broadcast(self, value):
        return value

    def concatenate(self, array):
        return array

    def barrier(self):
        pass

    def books(self, engine, books):
        return books

    def owned_rows(self, engine):
        raise TypeError("SerialRun.owned_rows: a serial engine's particles are all its own (Engine.particles)")

    def contact_records(self, engine):
        return engine.neighbors.records()
