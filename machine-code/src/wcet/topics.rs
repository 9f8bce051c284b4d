//! One topic's job of a publisher task. A publisher task's job (one poll of `serve_level`) takes
//! every release due at its levels and samples each release's topic: its longest path takes the
//! release loop at its stated worst and every topic's sample on each pass, which bounds the job but
//! not what the response-time analysis charges, one job per release of one topic.
//!
//! The bounds file's `topics` states, for the publisher's release loop, the groups of topics that
//! share a sample and the functions only their samples call (each topic family's sample is a
//! function of its own, not inlined). The bound of a topic's job is then the task's bound with
//!
//! * the release loop charged one pass in total per job (as `totals` charges a loop: its way out on
//!   every entry, and one longest iteration once), and
//! * every call of a function another group names left out of every function of the job, with the
//!   blocks only such a call leads to ([`super::cfg::Cfg::without`]); a function left with no way
//!   to its return is left out where it is called, in turn;
//! * the group's own `waits` and `loops` in place of the file's at the same places (the bus waits
//!   of the devices this group's sample addresses, the frames its sample holds).
//!
//! Sound per release: a job that serves k ≥ 1 releases of topics T₁ … T_k runs the task's code
//! around the loop once and one iteration per release, where each iteration of T_i calls only
//! T_i's functions; so it costs at most Σ (around + iteration(T_i)) ≤ Σ bound(T_i). A job that
//! serves none (woken by a schedule change) runs the code around the loop alone, within any topic's
//! bound. docs/analysis.md ("One topic's job") states it with what the model charges it to.
use super::bounds::{same_file, BoundsFile, PerTopic, TopicGroup, TotalBound};

impl PerTopic {
    /// The groups present in `image`: those with a function of theirs in it (a group may be one
    /// revision's, its functions built only there). A topic may be in groups of several revisions,
    /// of which one image holds at most one.
    pub fn present<'t>(&'t self, image: &crate::Image) -> Vec<&'t TopicGroup> {
        self.groups
            .iter()
            .filter(|g| g.functions.iter().any(|f| image.function_named(f).is_ok()))
            .collect()
    }

    /// The functions a job of `group` does not call: every other present group's, but its own.
    pub fn excluded(group: &TopicGroup, present: &[&TopicGroup]) -> Vec<String> {
        present
            .iter()
            .filter(|g| g.name != group.name)
            .flat_map(|g| g.functions.iter().cloned())
            .filter(|f| !group.functions.contains(f))
            .collect()
    }

    /// A topic of `group` that another present group holds too (which of them samples it is not
    /// told apart).
    pub fn shared_topic<'t>(group: &'t TopicGroup, present: &[&TopicGroup]) -> Option<&'t str> {
        group
            .topics
            .iter()
            .find(|t| {
                present
                    .iter()
                    .any(|g| g.name != group.name && g.topics.contains(t))
            })
            .map(String::as_str)
    }

    /// The release loop, `function at file:line`.
    pub fn at(&self) -> String {
        format!("{} at {}:{}", self.function, self.file, self.line)
    }
}

impl BoundsFile {
    /// This file as a job of `group`'s topics reads it: the release loop one pass in total per job,
    /// the group's waits and loops in place of the file's at their places, its transaction caps in
    /// place of the file's of the same function (the file's other
    /// statements unchanged).
    pub fn for_topic_group(&self, per_topic: &PerTopic, group: &TopicGroup) -> BoundsFile {
        let mut file = self.clone();
        file.totals.retain(|t| {
            !(t.function == per_topic.function
                && t.line == per_topic.line
                && same_file(&per_topic.file, &t.file))
        });
        file.totals.push(TotalBound {
            function: per_topic.function.clone(),
            file: per_topic.file.clone(),
            line: per_topic.line,
            passes: 1,
            reason: format!(
                "one release per job of topic group {} ({})",
                group.name, per_topic.reason
            ),
        });
        for l in &group.loops {
            file.loops.retain(|x| {
                !(x.function == l.function && x.line == l.line && same_file(&l.file, &x.file))
            });
            file.loops.push(l.clone());
        }
        for w in &group.waits {
            file.waits.retain(|x| {
                !(x.function == w.function && x.line == w.line && same_file(&w.file, &x.file))
            });
            file.waits.push(w.clone());
        }
        for c in &group.transactions {
            file.transactions.retain(|x| x.function != c.function);
            file.transactions.push(c.clone());
        }
        for c in &group.calls {
            file.calls.retain(|x| x.function != c.function);
            file.calls.push(c.clone());
        }
        file
    }
}
