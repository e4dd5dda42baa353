//! The assembled system: state layout, the right-hand side that wires the gas, fluid and
//! engine modules together, and the projections applied after each sub-step.

use super::engine::{Chamber, EngineSide};
use super::fluid::{Feed, Tank};
use super::gas::{Bottle, CheckValve, Helium, GAS_LAMINAR_FRAC};
use super::integrator::Rhs;
use super::regulator::{OutletGas, Regulator};
use oils_shared::ENGINE_COUNT;

/// Number of continuous states.
pub const N_STATES: usize = 20 + 6 * ENGINE_COUNT;

/// Propellant index: fuel (MMH).
pub const FUEL: usize = 0;
/// Propellant index: oxidiser (MON-3).
pub const OX: usize = 1;

/// Where each state lives in the state vector.
pub mod ix {
    /// Helium mass in the bottle, kg.
    pub const BOTTLE_MASS: usize = 0;
    /// Helium temperature in the bottle, K.
    pub const BOTTLE_TEMP: usize = 1;
    /// Bottle wall temperature, K.
    pub const WALL_TEMP: usize = 2;
    /// Regulator poppet lift, m.
    pub const POPPET_LIFT: usize = 3;
    /// Regulator poppet velocity, m/s.
    pub const POPPET_VEL: usize = 4;
    /// Helium mass in the regulator outlet volume, kg.
    pub const REG_OUT_MASS: usize = 5;
    /// Ullage helium mass of tank `p`, kg.
    pub const fn ullage_mass(p: usize) -> usize {
        6 + 5 * p
    }
    /// Ullage temperature of tank `p`, K.
    pub const fn ullage_temp(p: usize) -> usize {
        7 + 5 * p
    }
    /// Liquid mass in tank `p`, kg.
    pub const fn liquid_mass(p: usize) -> usize {
        8 + 5 * p
    }
    /// Flow in the main line of propellant `p`, kg/s.
    pub const fn main_flow(p: usize) -> usize {
        9 + 5 * p
    }
    /// Manifold pressure of propellant `p`, Pa.
    pub const fn manifold_pressure(p: usize) -> usize {
        10 + 5 * p
    }
    /// Cumulative mass of propellant `p` injected into the chambers, kg.
    pub const fn ejected(p: usize) -> usize {
        16 + p
    }
    /// Branch flow of engine `e`, propellant `p`, kg/s.
    pub const fn branch_flow(e: usize, p: usize) -> usize {
        18 + 6 * e + p
    }
    /// Dome liquid mass of engine `e`, propellant `p`, kg.
    pub const fn dome_mass(e: usize, p: usize) -> usize {
        20 + 6 * e + p
    }
    /// Chamber pressure of engine `e`, Pa.
    pub const fn chamber_pressure(e: usize) -> usize {
        22 + 6 * e
    }
    /// Cumulative thrust impulse of engine `e`, N s.
    pub const fn impulse(e: usize) -> usize {
        23 + 6 * e
    }
    /// Recent mean of the main line flow of propellant `p` (unsteady friction), kg/s.
    pub const fn main_flow_slow(p: usize) -> usize {
        18 + 6 * super::ENGINE_COUNT + p
    }
}

/// Valve positions at one instant: the time-dependent inputs of the right-hand side.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Actuation {
    /// Solenoid opening `[engine][propellant]`, 0-1.
    pub solenoid: [[f64; 2]; ENGINE_COUNT],
    /// TFCV valve position `[engine][propellant]`, 0-1.
    pub tfcv: [[f64; 2]; ENGINE_COUNT],
    /// Dribble weight `[engine][propellant]`: see `Solenoid::dribble_gate`.
    pub dribble: [[f64; 2]; ENGINE_COUNT],
}

/// Valve positions with the branch series resistances they imply, computed once per
/// sub-step boundary rather than in every evaluation.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Drive {
    /// Positions.
    pub act: Actuation,
    /// Series resistance of each branch `[engine][propellant]`, `None` when shut.
    pub series: [[Option<f64>; 2]; ENGINE_COUNT],
}

/// Algebraic quantities of the last evaluation (reported, never integrated).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Aux {
    /// Bottle pressure, Pa.
    pub bottle_pressure_pa: f64,
    /// Regulator outlet pressure, Pa.
    pub regulator_outlet_pa: f64,
    /// Regulator outlet temperature, K.
    pub regulator_outlet_k: f64,
    /// Helium flow through the regulator, kg/s.
    pub regulator_flow_kg_s: f64,
    /// Ullage pressure per tank, Pa.
    pub tank_pressure_pa: [f64; 2],
    /// Helium flow into each tank, kg/s.
    pub check_valve_flow_kg_s: [f64; 2],
    /// Injector flow `[engine][propellant]`, kg/s.
    pub injected_kg_s: [[f64; 2]; ENGINE_COUNT],
    /// Thrust per engine, N.
    pub thrust_n: [f64; ENGINE_COUNT],
}

/// Constants of the whole system plus the valve positions of the current sub-step.
#[derive(Debug, Clone)]
pub struct Plant {
    /// Helium properties.
    pub he: Helium,
    /// Bottle and latch valve.
    pub bottle: Bottle,
    /// Regulator.
    pub regulator: Regulator,
    /// Check valves (alike).
    pub check_valve: CheckValve,
    /// Tanks `[fuel, ox]`.
    pub tanks: [Tank; 2],
    /// Feeds `[fuel, ox]`.
    pub feeds: [Feed; 2],
    /// Engine sides `[fuel, ox]` (all engines alike).
    pub sides: [EngineSide; 2],
    /// Chamber and nozzle (all engines alike).
    pub chamber: Chamber,
    /// Valve positions at the start `[0]` and end `[1]` of the sub-step.
    pub drive: [Drive; 2],
    /// Algebraic outputs of the last evaluation.
    pub aux: Aux,
    /// Failures in force (all off unless a fault is injected).
    pub faults: PlantFaults,
}

/// Failures of the pressure-fed system, acting through the physics: a leak is a mass
/// flow out of a volume, a failed regulator a poppet held at a stop, a clogged injector
/// a smaller orifice (higher resistance: less flow at the same pressures). Everything downstream (pressures, flows, thrust) follows.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlantFaults {
    /// Poppet held at its stop: `Some(true)` wide open, `Some(false)` shut.
    pub regulator_held_open: Option<bool>,
    /// Helium leak from the bottle, flow area Cd A, m^2 (0: none).
    pub pressurant_leak_m2: f64,
    /// Propellant leak from each tank `[fuel, ox]`, kg/s (0: none).
    pub propellant_leak_kg_s: [f64; 2],
    /// Fraction of each injector's area `Cd A` left open `[engine][propellant]`
    /// (1: healthy, 0: blocked, the branch then passes nothing).
    pub injector_open_frac: [[f64; 2]; ENGINE_COUNT],
}

impl Default for PlantFaults {
    fn default() -> Self {
        Self {
            regulator_held_open: None,
            pressurant_leak_m2: 0.0,
            propellant_leak_kg_s: [0.0; 2],
            injector_open_frac: [[1.0; 2]; ENGINE_COUNT],
        }
    }
}

impl Rhs<N_STATES> for Plant {
    fn eval(
        &mut self,
        end: bool,
        y: &[f64; N_STATES],
        d: &mut [f64; N_STATES],
        jdiag: Option<&mut [f64; N_STATES]>,
    ) {
        let mut j = [0.0; N_STATES];
        let drive = &self.drive[end as usize];
        let other = &self.drive[1 - end as usize];
        let he = &self.he;

        // Gas module: bottle -> latch + regulator poppet -> outlet volume.
        let bottle_kg = y[ix::BOTTLE_MASS];
        let bottle_k = y[ix::BOTTLE_TEMP];
        let rho_b = bottle_kg / self.bottle.volume_m3;
        let p_b = he.pressure(rho_b, bottle_k);
        let h_b = he.enthalpy(rho_b, bottle_k);
        let outlet = OutletGas::new(
            he,
            y[ix::REG_OUT_MASS],
            self.regulator.outlet_volume_m3,
            h_b,
        );
        let lift = y[ix::POPPET_LIFT];
        let cd_a = self
            .bottle
            .in_series_with_latch(self.regulator.cd_area(lift));
        let reg_flow = he.orifice_flow(
            cd_a,
            p_b,
            rho_b,
            outlet.pressure_pa,
            outlet.density_kg_m3,
            GAS_LAMINAR_FRAC,
        );
        let (acc, dacc) =
            self.regulator
                .acceleration(lift, y[ix::POPPET_VEL], p_b, outlet.pressure_pa);
        d[ix::POPPET_LIFT] = y[ix::POPPET_VEL];
        d[ix::POPPET_VEL] = acc;
        j[ix::POPPET_VEL] = dacc;
        // A leak to space: choked flow through the leak's area (vacuum downstream).
        let leak = if self.faults.pressurant_leak_m2 > 0.0 {
            he.orifice_flow(
                self.faults.pressurant_leak_m2,
                p_b,
                rho_b,
                0.0,
                0.0,
                GAS_LAMINAR_FRAC,
            )
        } else {
            0.0
        };
        let br = self.bottle.rates(
            he,
            bottle_kg,
            bottle_k,
            y[ix::WALL_TEMP],
            p_b,
            rho_b,
            reg_flow + leak,
        );
        d[ix::BOTTLE_MASS] = -reg_flow - leak;
        d[ix::BOTTLE_TEMP] = br.dgas_temp_k_s;
        d[ix::WALL_TEMP] = br.dwall_temp_k_s;

        // Engines first: the manifolds need the sum of branch flows.
        let mut branch_sum = [0.0; 2];
        let mut ejected_rate = [0.0; 2];
        for e in 0..ENGINE_COUNT {
            let pc = y[ix::chamber_pressure(e)];
            let mut injected = [0.0; 2];
            for p in 0..2 {
                let flow = y[ix::branch_flow(e, p)];
                let dome = y[ix::dome_mass(e, p)];
                let open_frac = self.faults.injector_open_frac[e][p];
                let r = self.sides[p].rates(
                    flow,
                    dome,
                    drive.act.dribble[e][p],
                    drive.series[e][p].filter(|_| open_frac > 0.0),
                    other.series[e][p].unwrap_or(0.0),
                    y[ix::manifold_pressure(p)],
                    pc,
                    open_frac,
                );
                d[ix::branch_flow(e, p)] = r.dflow;
                j[ix::branch_flow(e, p)] = r.dflow_slope;
                let injected_kg_s = r.injected_kg_s;
                d[ix::dome_mass(e, p)] = flow - injected_kg_s;
                branch_sum[p] += flow;
                injected[p] = injected_kg_s;
                ejected_rate[p] += injected_kg_s;
            }
            let (dpc, jpc) = self.chamber.pressure_rate(injected[OX], injected[FUEL], pc);
            d[ix::chamber_pressure(e)] = dpc;
            j[ix::chamber_pressure(e)] = jpc;
            let thrust = self.chamber.thrust_n(pc);
            d[ix::impulse(e)] = thrust;
            self.aux.thrust_n[e] = thrust;
            self.aux.injected_kg_s[e] = injected;
        }

        // Fluid module: check valve -> ullage; tank -> main line -> manifold.
        let mut cv_total = 0.0;
        for p in 0..2 {
            let tank = &self.tanks[p];
            let gas = y[ix::ullage_mass(p)];
            let temp = y[ix::ullage_temp(p)];
            let liquid = y[ix::liquid_mass(p)];
            let main = y[ix::main_flow(p)];
            let (_, p_u) = tank.ullage_state(he, gas, temp, liquid);
            // A leak drains the tank (while it holds liquid) and leaves the vehicle.
            let leak = if liquid > 0.0 {
                self.faults.propellant_leak_kg_s[p]
            } else {
                0.0
            };
            let cv = self
                .check_valve
                .flow(outlet.pressure_pa, outlet.density_kg_m3, p_u);
            cv_total += cv;
            d[ix::ullage_mass(p)] = cv;
            d[ix::ullage_temp(p)] =
                tank.ullage_dtemp(he, gas, temp, p_u, cv, outlet.enthalpy_j_kg, main + leak);
            d[ix::liquid_mass(p)] = -main - leak;
            let p_m = y[ix::manifold_pressure(p)];
            let slow = y[ix::main_flow_slow(p)];
            let feed = &self.feeds[p];
            let (dmain, jmain) = feed.main_line(tank.outlet_factor(liquid) * p_u, p_m, main, slow);
            d[ix::main_flow_slow(p)] = (main - slow) / feed.unsteady_time_s;
            d[ix::main_flow(p)] = dmain;
            j[ix::main_flow(p)] = jmain;
            d[ix::manifold_pressure(p)] = self.feeds[p].manifold_stiffness * (main - branch_sum[p]);
            d[ix::ejected(p)] = ejected_rate[p] + leak;
            self.aux.tank_pressure_pa[p] = p_u;
            self.aux.check_valve_flow_kg_s[p] = cv;
        }
        d[ix::REG_OUT_MASS] = reg_flow - cv_total;

        self.aux.bottle_pressure_pa = p_b;
        self.aux.regulator_outlet_pa = outlet.pressure_pa;
        self.aux.regulator_outlet_k = outlet.temperature_k;
        self.aux.regulator_flow_kg_s = reg_flow;
        if let Some(jd) = jdiag {
            *jd = j;
        }
    }
}

impl Plant {
    /// Sets the valve positions of slot 0 (sub-step start) or 1 (end).
    #[inline]
    pub fn set_actuation(&mut self, slot: usize, act: &Actuation) {
        let d = &mut self.drive[slot];
        d.act = *act;
        for e in 0..ENGINE_COUNT {
            for p in 0..2 {
                d.series[e][p] =
                    self.sides[p].series_resistance(act.solenoid[e][p], act.tfcv[e][p]);
            }
        }
    }

    /// Constraints applied after each sub-step: the poppet's hard stops, and no flow
    /// through a branch whose valve is shut or whose injector is blocked.
    #[inline]
    pub fn project(&self, y: &mut [f64; N_STATES]) {
        let (mut lift, mut vel) = (y[ix::POPPET_LIFT], y[ix::POPPET_VEL]);
        self.regulator.apply_stops(&mut lift, &mut vel);
        if let Some(open) = self.faults.regulator_held_open {
            lift = if open { self.regulator.max_lift_m } else { 0.0 };
            vel = 0.0;
        }
        y[ix::POPPET_LIFT] = lift;
        y[ix::POPPET_VEL] = vel;
        for e in 0..ENGINE_COUNT {
            for p in 0..2 {
                if self.drive[1].series[e][p].is_none()
                    || self.faults.injector_open_frac[e][p] <= 0.0
                {
                    y[ix::branch_flow(e, p)] = 0.0;
                }
            }
        }
    }
}
